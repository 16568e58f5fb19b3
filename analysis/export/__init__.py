"""Logs out to the tools engineers already use: MF4 (asammdf, CANedge's layout), Vector BLF and
ASC and candump (python-can's writers), and a viewer-ready MCAP for Foxglove (JSON with JSON
Schemas). One file per input log, named after it; nothing is written over (an input, an earlier
export or any file), and each file appears only once complete.

Public: `FORMATS`, `target_name`, `export_logs`.
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from haulprofile.contract.private_files import FILE_MODE, make_dirs

from haulprofile.contract import CAN_FRAMES

from ..errors import UserError
from ..ingest import foreign
from ..ingest.logs import is_mcap
from . import source

FORMATS = {"mf4": ".mf4", "blf": ".blf", "asc": ".asc", "candump": ".log", "foxglove": ".foxglove.mcap"}
"""Format → suffix of the exported file."""
DECODED = ("mf4", "foxglove")
"""Formats that also carry the decoded signals table."""


class ExportError(UserError):
    pass


@dataclass
class Exported:
    source: Path
    target: Path
    frames: int
    signals: int
    """Rows of decoded signals written (0 for formats without them)."""

    def line(self) -> str:
        extra = f", {self.signals} rows of decoded signals" if self.signals else ""
        return f"{self.source} -> {self.target}: {self.frames} CAN frames{extra}"


def target_name(path: Path, to: str) -> str:
    name = Path(path).name
    for suffix in (".mcap", ".mf4", ".MF4", ".blf", ".asc", ".log", ".trc", ".csv"):
        if name.endswith(suffix):
            name = name[: -len(suffix)]
            break
    return name + FORMATS[to]


def row_times_ns(table, summary: dict) -> np.ndarray:
    """Time of each row of a signals table on the ingest's clock [ns]: ``t0_mono_ns`` plus ``time_s``,
    plus the time taken out of each shortened silence before the row."""
    rows = np.arange(len(table))
    times = np.int64(summary["t0_mono_ns"]) + np.round(table["time_s"].to_numpy(float) * 1e9).astype(np.int64)
    for gap in summary.get("gaps_shortened", []):
        times[rows >= gap["row"]] += np.int64(round(gap["removed_s"] * 1e9))
    return times


def _decoded(path: Path, content: source.LogContent, rate_hz: float, dbc, private: bool, say):
    from ..ingest import ingest_logs
    from ..signals import without_positions

    try:
        table, summary = ingest_logs([path], rate_hz=rate_hz, dbc=dbc)
    except UserError as exc:
        say(f"warning: {path}: no decoded signals in the export ({exc})")
        return None, None
    rows = row_times_ns(table, summary) - np.int64(content.ingest_shift_ns)
    return (without_positions(table) if private else table), rows


def _check_targets(paths: list[Path], out_dir: Path, to: str) -> list[Path]:
    targets = [out_dir / target_name(p, to) for p in paths]
    seen: dict[Path, Path] = {}
    for path, target in zip(paths, targets):
        if target in seen:
            raise ExportError(f"{path} and {seen[target]} would both export to {target}; export them into "
                              f"different directories")
        seen[target] = path
        if target.exists() or target.is_symlink():
            raise ExportError(f"{target} exists; exports never write over a file (remove it or choose another "
                              f"output directory)")
    return targets


def _publish(partial: Path, target: Path) -> None:
    """Give the finished ``partial`` its name, refusing (not replacing) a file that appeared meanwhile."""
    try:
        os.link(partial, target)
    except FileExistsError:
        raise ExportError(f"{target} appeared while exporting; it was left as it is") from None
    finally:
        partial.unlink(missing_ok=True)


def export_logs(paths, to: str, out_dir: Path, private: bool = False, rate_hz: float = 10.0, dbc=None,
                say: Callable[[str], None] | None = None) -> list[Exported]:
    """Export each log of ``paths`` (MCAP logs, directories, other loggers' CAN logs) as ``to``
    (a key of `FORMATS`) into ``out_dir``; with ``private`` no wall-clock time, position topic or
    position/date PGN leaves the program (`source`)."""
    from ..ingest.logs import expand

    say = say or (lambda _msg: None)
    if to not in FORMATS:
        raise ExportError(f"unknown export format {to!r}; one of {', '.join(FORMATS)}")
    files = expand(paths)
    for path in files:
        if not is_mcap(path) and foreign.kind(path) not in ("can", "blf", "mf4"):
            raise ExportError(f"{path}: not an MCAP log or another logger's CAN log (candump, ASC, BLF, TRC, "
                              f"python-can CSV, MF4); a signals table or GPS log has no CAN frames to export")
    out_dir = Path(out_dir)
    targets = _check_targets(files, out_dir, to)
    make_dirs(out_dir)
    done = []
    for path, target in zip(files, targets):
        handle, name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".partial" + FORMATS[to], dir=out_dir)
        os.close(handle)
        partial = Path(name)
        try:
            if to == "mf4" and is_mcap(path):
                partial.unlink()  # asammdf's save renames rather than replaces an existing file
                frames, rows = _stream_mf4(path, partial, private, rate_hz, dbc, say)
            else:
                frames, rows = _export(path, partial, to, private, rate_hz, dbc, say)
            os.chmod(partial, FILE_MODE)
            _publish(partial, target)
        finally:
            partial.unlink(missing_ok=True)
        done.append(Exported(path, target, frames, rows))
        say(done[-1].line())
    return done


def _export(path: Path, partial: Path, to: str, private: bool, rate_hz: float, dbc, say) -> tuple[int, int]:
    """One log, read whole, written as ``to``; (frames, decoded rows) written."""
    content = source.load(path, private=private, everything=to == "foxglove")
    table, rows = _decoded(path, content, rate_hz, dbc, private, say) if to in DECODED else (None, None)
    _write(content, partial, to, table, rows)
    return len(content.frames), 0 if table is None else len(table)


def _stream_mf4(path: Path, partial: Path, private: bool, rate_hz: float, dbc, say) -> tuple[int, int]:
    """An MCAP log as MF4 in one read: each window's frames go to asammdf while the ingest decodes
    it; the decoded signals and the clock's offset are added at the end."""
    from ..ingest import ingest_logs
    from ..signals import without_positions
    from .mf4 import Mf4Writer

    state: dict = {}
    clock = source.Clock()

    def on_window(_index, _shift, window) -> None:
        frames = window.topic_records(CAN_FRAMES.name)
        if "writer" not in state:
            firsts = [int(frames["t_mono_ns"].min())] if len(frames) else []
            state["writer"] = Mf4Writer(min(firsts + [int(window.publish_times_ns.min())]))
        clock.add(window)
        state["writer"].add(source.without_private_frames(frames) if private else frames)

    try:
        table, summary = ingest_logs([path], rate_hz=rate_hz, dbc=dbc, on_window=on_window)
        rows = row_times_ns(table, summary)
    except UserError as exc:
        if "writer" not in state:
            raise
        say(f"warning: {path}: no decoded signals in the export ({exc})")
        table = rows = None
    writer = state.get("writer") or Mf4Writer()
    writer.finish(partial, 0 if private else clock.offset_ns(),
                  without_positions(table) if private and table is not None else table, rows)
    return writer.frames, 0 if table is None else len(table)


def _write(content: source.LogContent, partial: Path, to: str, table, rows) -> None:
    if to == "mf4":
        from . import mf4

        partial.unlink()  # asammdf's save renames rather than replaces an existing file
        mf4.write(content, partial, table, rows)
    elif to == "foxglove":
        from . import foxglove

        with open(partial, "wb") as stream:
            foxglove.write(content, stream, table, rows)
    else:
        from . import bus_logs

        bus_logs.write(content, partial, to)
