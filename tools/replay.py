"""Replay the CAN frames of haulprofile MCAP logs onto a python-can bus.

    python tools/replay.py LOG.mcap [LOG.mcap ...] --interface socketcan --channel vcan0
    python tools/replay.py LOG.mcap --interface virtual --channel test --fast
    python tools/replay.py LOG.mcap --interface socketcan --channel can0 --bitrate 250000 --speed 2

Plays every received frame of `/can/frames` (in file order) with its original spacing
(``--realtime``, the default, optionally ``--speed`` times faster) or as fast as the bus takes them
(``--fast``). Frames the logger itself sent (flagged TX: OBD-II requests, J1939 requests, flow
control) are left out unless ``--include-tx``; error frames are never sent. Needs only the logger
extra (python-can, mcap): it runs on the Pi. Set up a virtual CAN on a Linux host with
``ip link add dev vcan0 type vcan && ip link set up vcan0``; a real interface is brought up (with
its bitrate) outside this tool, as the logger's is.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from haulprofile import contract  # noqa: E402
from haulprofile.contract.reader import packed_records  # noqa: E402

SEND_RETRY_S = 0.001
"""Wait before re-sending a frame the interface refused (its transmit queue is full) [s]."""
SEND_RETRIES = 1000


class ReplayError(Exception):
    """Bad input or a bus that cannot be opened: one line for the user."""


@dataclass
class ReplayStats:
    sent: int = 0
    skipped_tx: int = 0
    skipped_error: int = 0
    max_late_s: float = 0.0
    duration_s: float = 0.0


def frames_of(paths: list[Path], include_tx: bool = False, stats: ReplayStats | None = None):
    """``(t_mono_ns, can.Message)`` of the logs' received frames in file order."""
    import can
    stats = stats if stats is not None else ReplayStats()
    for path in paths:
        for records in packed_records(path, contract.CAN_FRAMES):
            for record in records:
                flags = int(record["flags"])
                if flags & contract.CAN_FLAG_ERROR:
                    stats.skipped_error += 1
                    continue
                if flags & contract.CAN_FLAG_TX and not include_tx:
                    stats.skipped_tx += 1
                    continue
                dlc = int(record["dlc"])
                yield int(record["t_mono_ns"]), can.Message(
                    arbitration_id=int(record["arbitration_id"]), is_extended_id=bool(flags & contract.CAN_FLAG_EXTENDED),
                    is_remote_frame=bool(flags & contract.CAN_FLAG_REMOTE), dlc=dlc,
                    data=b"" if flags & contract.CAN_FLAG_REMOTE else bytes(record["data"][:dlc]))


def _send(bus, message) -> None:
    import can
    for _ in range(SEND_RETRIES):
        try:
            bus.send(message, timeout=0.1)
            return
        except can.CanOperationError:  # ENOBUFS: the interface's queue is full at --fast
            time.sleep(SEND_RETRY_S)
    raise ReplayError("the bus refuses frames (bus-off? no other node acknowledging?)")


def replay(paths: list[Path], bus, realtime: bool = True, speed: float = 1.0, include_tx: bool = False) -> ReplayStats:
    """Send the logs' frames on ``bus``; with ``realtime`` the original spacing divided by ``speed``."""
    stats = ReplayStats()
    start = time.perf_counter()
    first_ns = None
    for t_ns, message in frames_of(paths, include_tx, stats):
        if realtime:
            if first_ns is None:
                first_ns = t_ns
            due = start + (t_ns - first_ns) * 1e-9 / speed
            wait = due - time.perf_counter()
            if wait > 0:
                time.sleep(wait)
            else:
                stats.max_late_s = max(stats.max_late_s, -wait)
        _send(bus, message)
        stats.sent += 1
    stats.duration_s = time.perf_counter() - start
    return stats


def open_bus(interface: str, channel: str, bitrate: int | None):
    import can
    kwargs = {"interface": interface, "channel": channel}
    if bitrate is not None and interface not in ("virtual", "socketcan"):
        kwargs["bitrate"] = bitrate  # socketcan's bitrate is the interface's (ip link / networkd)
    try:
        return can.Bus(**kwargs)
    except (OSError, ValueError, ImportError, can.CanError) as exc:
        raise ReplayError(f"cannot open {interface} {channel}: {exc}") from None


def check_logs(paths: list[Path]) -> None:
    for path in paths:
        if not path.is_file():
            raise ReplayError(f"{path}: no such file")
        with open(path, "rb") as stream:
            if stream.read(8) != b"\x89MCAP0\r\n":
                raise ReplayError(f"{path}: not an MCAP file")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="replay.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("logs", nargs="+", type=Path, help="haulprofile MCAP logs, played in the order given")
    parser.add_argument("--interface", default="socketcan", help="python-can interface (socketcan, virtual, ...)")
    parser.add_argument("--channel", required=True, help="vcan0, can0, or a virtual channel name")
    parser.add_argument("--bitrate", type=int, default=None,
                        help="for interfaces that set it themselves; socketcan's is set with ip link / networkd")
    timing = parser.add_mutually_exclusive_group()
    timing.add_argument("--realtime", action="store_true", help="original timing (default)")
    timing.add_argument("--fast", action="store_true", help="as fast as the bus takes the frames")
    parser.add_argument("--speed", type=float, default=1.0, help="with --realtime: this many times faster")
    parser.add_argument("--include-tx", action="store_true", help="also send the frames the logger itself sent")
    args = parser.parse_args(argv)
    try:
        if args.speed <= 0:
            raise ReplayError(f"--speed must be > 0, got {args.speed}")
        check_logs(args.logs)
        bus = open_bus(args.interface, args.channel, args.bitrate)
        try:
            stats = replay(args.logs, bus, realtime=not args.fast, speed=args.speed, include_tx=args.include_tx)
        finally:
            bus.shutdown()
    except ReplayError as exc:
        print(f"replay: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    print(f"replay: {stats.sent} frames in {stats.duration_s:.2f} s on {args.interface} {args.channel} "
          f"(left out: {stats.skipped_tx} sent by the logger, {stats.skipped_error} error frames; "
          f"latest frame {stats.max_late_s * 1e3:.1f} ms behind its time)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
