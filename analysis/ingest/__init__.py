"""Ingest: MCAP logs (whole, cut or damaged), foreign CAN logs or signals tables → the signals table.

Public entry points:

* `read_logs(paths, rate_hz=10.0, dbc=None, progress=False)` → the aligned signals table.
* `ingest_logs(...)` → (signals table, summary dict) — what `stage` and ``analyze signals`` use.
* `iter_log_messages(paths)` → every recoverable MCAP message, in time order across files.
* `read_frames(paths)` → raw CAN records and IMU records (contract dtypes) and JSON records.
* the pipeline's ingest stage is `analysis.ingest.stage.ingest_stage`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np
import pandas as pd

from .. import checks
from .. import signals as signals_table
from . import align
from . import dbc as dbc_module
from . import foreign
from .columns import build_table
from .logs import (LogArrays, LogError, LogMessage, Timeline, expand, is_mcap, iter_log_messages, iter_log_windows,
                   read_frames)
from .table import BLOCK_FRAMES, Ingest

__all__ = ["read_logs", "ingest_logs", "iter_log_messages", "read_frames", "LogArrays",
           "LogMessage", "Timeline", "expand"]


def _progress(total: int, enabled: bool):
    from tqdm import tqdm

    return tqdm(total=total, unit="B", unit_scale=True, disable=not enabled, desc="ingest", leave=False)


def ingest_logs(paths, rate_hz: float = 10.0, dbc: str | Path | None = None, progress: bool = False,
                say: Callable[[str], None] | None = None, on_window: Callable | None = None
                ) -> tuple[pd.DataFrame, dict]:
    """Signals table [SI units, one row per 1/rate_hz s] and summary of logs or signals tables;
    ``on_window(file index, time shift, window)`` sees each MCAP window before it is decoded (an
    export that writes while the ingest reads)."""
    say = say or (lambda _msg: None)
    checks.rate_hz(rate_hz)
    files = expand(paths)
    tables = [p for p in files if signals_table.is_signals_path(p)]
    if tables:
        if len(tables) != len(files):
            raise LogError("give either logs or signals tables, not both")
        frame = signals_table.combine(tables, say)
        return frame, {"inputs": [str(p) for p in tables], "source": "signals table",
                       **signals_table.describe(frame)}
    files = checks.drop_same_content(files, say)
    mcap_files = [p for p in files if is_mcap(p)]
    other = [p for p in files if p not in mcap_files]
    kinds = {p: foreign.kind(p) for p in other}
    unknown = [p for p in other if kinds[p] is None]
    if unknown:
        raise LogError(f"{unknown[0]}: not an MCAP log, a candump/ASC/BLF/MF4 CAN log, an NMEA/UBX GPS log "
                       f"or a signals table")
    if mcap_files and other:
        raise LogError("give either MCAP logs or other loggers' CAN logs, not both in one run")
    database = dbc_module.load(dbc) if dbc is not None else None
    ingest = Ingest(rate_hz, database)
    timeline = Timeline()
    with _progress(sum(p.stat().st_size for p in files), progress) as bar:
        if mcap_files:
            _feed_mcap(ingest, mcap_files, timeline, bar, on_window)
        for path in other:
            if kinds[path] == "gnss":
                _feed_gnss(ingest, path, bar)
            else:
                _feed_foreign(ingest, path, bar)
    ingest.finish_streams()
    try:
        frame, summary = build_table(ingest)
    except LogError as exc:
        damage = "; ".join(f"{Path(r.path).name}: {r.warning()}" for r in timeline.reports if r.warning())
        raise LogError(f"{exc}" + (f" ({damage})" if damage else "")) from None
    warnings = [w for w in (r.warning() for r in timeline.reports) if w]
    warnings += [w for w in map(foreign.cut_short, other) if w]
    shortened = summary["gaps_shortened"]
    if shortened:
        longest = max(g["removed_s"] for g in shortened)
        warnings.append(f"{len(shortened)} silence(s) between recordings longer than {align.MAX_GAP_S:.0f} s "
                        f"(longest {longest / 3600:.1f} h) shortened to {align.KEPT_GAP_S:.0f} s of gap rows each: "
                        f"time_s counts recorded time, wall_time_ns keeps the real time")
    if "imu-scale" in ingest.notes:
        warnings.append("IMU channel metadata has no usable accel_scale_mps2_per_lsb (missing, or not a finite "
                        "1e-6 to 1 m/s^2 per count): accel_x/y/z_mps2 left out")
    for line in warnings:
        say(f"warning: {line}")
    summary.update({
        "inputs": [str(p) for p in files],
        "files": [{"path": r.path, "bytes": r.file_bytes, "recovered_bytes": r.read_bytes, "complete": r.complete,
                   "chunks": r.chunks, "bad_chunks": r.bad_chunks, "skipped_bytes": r.skipped_bytes,
                   "messages": r.messages, "unattributed_messages": r.unattributed_messages}
                  for r in timeline.reports],
        "warnings": warnings,
    })
    return frame, summary


def _feed_mcap(ingest: Ingest, files: list[Path], timeline: Timeline, bar, on_window=None) -> None:
    done = 0
    for index, offset, window in iter_log_windows(files, timeline):
        if on_window is not None:
            on_window(index, offset, window)
        ingest.feed_window(window, offset)
        position = sum(r.file_bytes for r in timeline.reports[:-1]) + timeline.reports[index].read_bytes
        if position - done > 1 << 24:
            bar.update(position - done)
            done = position


def _feed_foreign(ingest: Ingest, path: Path, bar) -> None:
    frames, (mono, wall) = foreign.read_can_log(path)
    if len(wall):
        # Foreign logs go on their own wall clock, so files of one truck line up in time.
        frames = frames.copy()
        frames["t_mono_ns"] += np.uint64(int(wall[0] - mono[0]))
        mono = mono + (wall[0] - mono[0])
        ingest.log_pairs[0].extend(mono.tolist())
        ingest.log_pairs[1].extend(wall.tolist())
    ingest.topic_counts[str(path)] = len(frames)
    for start in range(0, len(frames), BLOCK_FRAMES):
        ingest.feed_frames(frames[start:start + BLOCK_FRAMES])
    bar.update(path.stat().st_size)


def _feed_gnss(ingest: Ingest, path: Path, bar) -> None:
    """A GPS-only receiver log: its fixes as ``/gps/fix`` records on their UTC time line."""
    from haulprofile import contract

    from .gnss import read_fixes
    from .table import JSON_FIELDS, JsonTopic

    fixes = read_fixes(path)
    if not fixes:
        raise LogError(f"{path}: NMEA/UBX GPS log without a single position fix")
    stream = ingest.json.setdefault(contract.GPS_FIX.name, JsonTopic(JSON_FIELDS[contract.GPS_FIX.name]))
    stream.add_payloads([contract.encode_json(fix) for fix in fixes])
    dated = [f["t_mono_ns"] for f in fixes if f.get("gps_time_utc_ns") is not None]
    ingest.log_pairs[0].extend(dated[:1] + dated[-1:])
    ingest.log_pairs[1].extend(dated[:1] + dated[-1:])
    ingest.topic_counts[str(path)] = len(fixes)
    bar.update(path.stat().st_size)


def read_logs(paths, rate_hz: float = 10.0, dbc: str | Path | None = None, progress: bool = False) -> pd.DataFrame:
    """The signals table of logs (columns of `analysis.signals`; absent sources, absent columns).

    The summary is in ``frame.attrs["ingest"]``.
    """
    frame, summary = ingest_logs(paths, rate_hz=rate_hz, dbc=dbc, progress=progress)
    frame.attrs["ingest"] = summary
    return frame
