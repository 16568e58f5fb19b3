"""CAN logs of other loggers as raw CAN record arrays (contract dtype), ready for the same decoding;
which kind of log a file is, by its content (`kind`), GPS-only receiver logs included (`gnss`).

candump ``.log``, Vector ``.asc`` and ``.blf``, PEAK ``.trc`` and python-can's own ``.csv`` through
python-can's readers; CSS Electronics
CANedge ``.mf4`` through asammdf, whole columns at a time. Timestamps become nanoseconds on the
record's ``t_mono_ns``; the wall clock is returned beside them as (time, wall) pairs when the
format knows it (epoch timestamps, MF4 start time).
"""

from __future__ import annotations

import gc
import logging
import re
import sys
from pathlib import Path

import numpy as np

from haulprofile.contract import CAN_FLAG_ERROR, CAN_FLAG_EXTENDED, CAN_FLAG_REMOTE, CAN_FLAG_TX, CAN_FRAME_DTYPE

from ..errors import UserError

PYTHON_CAN_SUFFIXES = {".log", ".asc", ".blf", ".trc"}
PYTHON_CAN_CSV_HEADER = b"timestamp,arbitration_id,extended,remote,error,dlc,data"
"""The header line of python-can's ``CSVWriter``: a ``.csv`` that starts with it is a CAN log, not a table."""
MF4_SUFFIXES = {".mf4"}
GNSS_SUFFIXES = {".nmea", ".ubx"}
SUFFIXES = PYTHON_CAN_SUFFIXES | MF4_SUFFIXES | GNSS_SUFFIXES
SNIFF_BYTES = 4096
_EPOCH_2000_S = 946_684_800.0


class ForeignLogError(UserError):
    pass


def kind(path: str | Path) -> str | None:
    """What a foreign log holds, by its content first (a receiver's ``.log`` is no candump file):
    ``"mf4"``, ``"blf"``, ``"gnss"`` (raw NMEA/UBX), ``"can"`` (candump, ASC by suffix), or None."""
    path = Path(path)
    try:
        with open(path, "rb") as handle:
            head = handle.read(SNIFF_BYTES)
    except OSError:
        return None
    if head[:8] in (b"MDF     ", b"UnFinMF "):
        return "mf4"
    if head[:4] == b"LOGG":
        return "blf"
    from .gnss import looks_like_gnss

    if looks_like_gnss(head):
        return "gnss"
    suffix = path.suffix.lower()
    if suffix == ".csv":
        return "can" if head.lstrip(b"\xef\xbb\xbf").startswith(PYTHON_CAN_CSV_HEADER) else None
    if suffix in MF4_SUFFIXES:
        return "mf4"
    if suffix in PYTHON_CAN_SUFFIXES:
        return "can"
    return None


def is_foreign(path: str | Path) -> bool:
    return kind(path) is not None


def read_can_log(path: str | Path) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """(CAN records, (t_mono_ns, wall_ns) pairs) of a foreign CAN log (no CAN records for a GNSS log)."""
    path = Path(path)
    what = kind(path)
    if what == "gnss":
        return np.zeros(0, CAN_FRAME_DTYPE), (np.zeros(0, np.int64), np.zeros(0, np.int64))
    if what == "mf4":
        return read_mf4(path)
    return read_python_can(path)


def cut_short(path: str | Path) -> str | None:
    """Why a foreign log is cut short (a truncated MF4), or None if nothing shows it."""
    path = Path(path)
    if kind(path) == "mf4":
        from .mf4_check import truncation

        reason = truncation(path)
        if reason:
            return f"{path.name}: MF4 file cut short, {reason}: the recording went on beyond what is read"
    return None


def read_python_can(path: Path) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]:
    import can

    rows = []
    try:
        with can.LogReader(str(path)) as reader:
            for msg in reader:
                flags = ((CAN_FLAG_EXTENDED if msg.is_extended_id else 0)
                         | (CAN_FLAG_REMOTE if msg.is_remote_frame else 0)
                         | (CAN_FLAG_ERROR if msg.is_error_frame else 0)
                         | (0 if msg.is_rx else CAN_FLAG_TX))
                data = bytes(msg.data[:8])
                channel = _channel_number(msg.channel)
                rows.append((int(round(msg.timestamp * 1e9)), msg.arbitration_id, flags, min(msg.dlc, 8),
                             channel & 0xFF, 0, tuple(data.ljust(8, b"\x00"))))
    except Exception as exc:  # noqa: BLE001 - python-can's parsers raise many types on damaged files
        if not rows:
            raise ForeignLogError(f"{path}: cannot read as a {path.suffix} CAN log ({exc})") from None
        # keep what was read before the damage, as for a cut MCAP log
    frames = np.array(rows, dtype=CAN_FRAME_DTYPE) if rows else np.zeros(0, CAN_FRAME_DTYPE)
    return frames, _epoch_pairs(frames)


def _channel_number(channel) -> int:
    """Bus index of a python-can channel: an int as it is, ``can1``/``vcan1`` its trailing number, else 0."""
    if isinstance(channel, int):
        return channel
    digits = re.search(r"(\d+)$", channel) if isinstance(channel, str) else None
    return int(digits.group(1)) if digits else 0


def _epoch_pairs(frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Timestamps after 2000-01-01 are taken as wall clock (candump and BLF write epoch times)."""
    if len(frames) and frames["t_mono_ns"][0] / 1e9 > _EPOCH_2000_S:
        t = frames["t_mono_ns"][[0, -1]].astype(np.int64)
        return t, t.copy()
    return np.zeros(0, np.int64), np.zeros(0, np.int64)


def read_mf4(path: Path) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """CAN data frames of every data group of a CANedge MF4 (``CAN_DataFrame.*`` channels); what
    asammdf would log about a damaged file is left out (the error or `cut_short` says it once)."""
    log = logging.getLogger("asammdf")
    disabled, log.disabled = log.disabled, True
    try:
        return _read_mf4(path)
    finally:
        log.disabled = disabled


def _read_mf4(path: Path) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]:
    mdf, error = _open_mdf(path)
    if error is not None:
        raise ForeignLogError(f"{path}: cannot read as MF4 ({error})")
    try:
        parts, start_ns = _mf4_frames(mdf)
    except Exception as exc:  # noqa: BLE001 - asammdf raises many types on damaged files
        parts = _cut_mf4_frames(path)
        if parts is None:
            raise ForeignLogError(f"{path}: cannot read the CAN frames of this MF4 ({type(exc).__name__}: {exc})") \
                from None
        parts, start_ns = parts
    finally:
        mdf.close()
    if not parts:
        raise ForeignLogError(f"{path}: MF4 file has no CAN_DataFrame channels (not a CAN bus log)")
    frames = np.concatenate(parts)
    frames = frames[np.argsort(frames["t_mono_ns"], kind="stable")]
    mono = frames["t_mono_ns"][[0, -1]].astype(np.int64)
    return frames, (mono, mono + start_ns)


def _cut_mf4_frames(path: Path) -> tuple[list[np.ndarray], int] | None:
    """The frames of a cut MF4 that asammdf cannot read as it is: a copy ending after a whole
    record (a CAN frame and its data bytes are two records, so a few ends are tried)."""
    import tempfile

    from asammdf import MDF

    from .mf4_check import whole_prefixes

    with tempfile.TemporaryDirectory() as folder:
        for length in whole_prefixes(path)[:4]:
            copy = Path(folder) / path.name
            with open(path, "rb") as source, open(copy, "wb") as target:
                target.write(source.read(length))
            try:
                with MDF(str(copy)) as mdf:
                    return _mf4_frames(mdf)
            except Exception:  # noqa: BLE001,S112 - asammdf raises many types; the next end may read
                continue
    return None


def _open_mdf(path: Path):
    """(MDF, None) or (None, the reason it cannot be read). asammdf leaves a half-built object whose
    ``__del__`` raises on a cut file; it is collected here, its complaint silenced, so the user sees
    only the one-line error."""
    from asammdf import MDF

    hook = sys.unraisablehook
    sys.unraisablehook = lambda _unraisable: None
    try:
        try:
            return MDF(str(path)), None
        except Exception as exc:  # asammdf raises many types for unreadable files
            error = f"{type(exc).__name__}: {exc}"
        gc.collect()
        return None, error
    finally:
        sys.unraisablehook = hook


def _mf4_frames(mdf) -> tuple[list[np.ndarray], int]:
    """Record arrays of the CAN data groups and the recording start [ns since epoch]."""
    parts = []
    for index, group in enumerate(mdf.groups):
        names = {c.name for c in group.channels}
        if "CAN_DataFrame.ID" not in names:
            continue
        get = lambda name: mdf.get(name, group=index, raw=True)  # noqa: E731
        ids = get("CAN_DataFrame.ID")
        data = get("CAN_DataFrame.DataBytes").samples
        dlc = get("CAN_DataFrame.DLC").samples.astype(np.uint8)
        ide = get("CAN_DataFrame.IDE").samples.astype(bool) if "CAN_DataFrame.IDE" in names else None
        channel = (get("CAN_DataFrame.BusChannel").samples.astype(np.uint8)
                   if "CAN_DataFrame.BusChannel" in names else np.zeros(len(dlc), np.uint8))
        frames = np.zeros(len(dlc), CAN_FRAME_DTYPE)
        frames["t_mono_ns"] = np.round(ids.timestamps * 1e9).astype(np.uint64)
        frames["arbitration_id"] = ids.samples.astype(np.uint32) & 0x1FFFFFFF
        extended = ide if ide is not None else ids.samples.astype(np.uint32) > 0x7FF
        frames["flags"] = np.where(extended, CAN_FLAG_EXTENDED, 0)
        frames["dlc"] = np.minimum(dlc, 8)
        frames["channel"] = channel
        width = min(8, data.shape[1]) if data.ndim == 2 else 0
        frames["data"][:, :width] = data[:, :width]
        # bytes beyond the DLC are zero (contract)
        frames["data"][np.arange(8)[None, :] >= frames["dlc"][:, None]] = 0
        parts.append(frames)
    return parts, int(mdf.start_time.timestamp() * 1e9)
