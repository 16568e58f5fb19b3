"""Ingest: MCAP logs (whole, cut or damaged), foreign CAN logs or signals tables → the signals table.

Public entry points:

* `read_logs(paths, rate_hz=10.0, dbc=None, progress=False)` → the aligned signals table.
* `ingest_logs(...)` → (signals table, summary dict) — what `stage` and ``analyze signals`` use.
* `iter_log_messages(paths)` → every recoverable MCAP message, in time order across files.
* `read_frames(paths)` → raw CAN records and IMU records (contract dtypes) and JSON records.
* `stage(ctx)` → the pipeline's ingest stage.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np
import pandas as pd

from .. import signals as signals_table
from ..errors import UserError
from . import dbc as dbc_module
from . import foreign
from .columns import build_table
from .logs import (LogArrays, LogError, LogMessage, Timeline, expand, is_mcap, iter_log_messages, iter_log_windows,
                   read_frames)
from .table import BLOCK_FRAMES, Ingest

__all__ = ["read_logs", "ingest_logs", "iter_log_messages", "read_frames", "stage", "LogArrays",
           "LogMessage", "Timeline", "expand"]


def _progress(total: int, enabled: bool):
    from tqdm import tqdm

    return tqdm(total=total, unit="B", unit_scale=True, disable=not enabled, desc="ingest", leave=False)


def ingest_logs(paths, rate_hz: float = 10.0, dbc: str | Path | None = None, progress: bool = False,
                say: Callable[[str], None] | None = None) -> tuple[pd.DataFrame, dict]:
    """Signals table [SI units, one row per 1/rate_hz s] and summary of logs or signals tables."""
    say = say or (lambda _msg: None)
    files = expand(paths)
    tables = [p for p in files if signals_table.is_signals_path(p)]
    if tables:
        if len(tables) != len(files):
            raise LogError("give either logs or signals tables, not both")
        frame = pd.concat([signals_table.read_signals(p) for p in tables], ignore_index=True)
        frame = signals_table.validate(frame, ", ".join(map(str, tables)))
        return frame, {"inputs": [str(p) for p in tables], "rows": len(frame), "source": "signals table"}
    mcap_files = [p for p in files if is_mcap(p)]
    other = [p for p in files if p not in mcap_files]
    unknown = [p for p in other if not foreign.is_foreign(p)]
    if unknown:
        raise LogError(f"{unknown[0]}: not an MCAP log, a .log/.asc/.blf/.mf4 CAN log or a signals table")
    if mcap_files and other:
        raise LogError("give either MCAP logs or other loggers' CAN logs, not both in one run")
    database = dbc_module.load(dbc) if dbc is not None else None
    ingest = Ingest(rate_hz, database)
    timeline = Timeline()
    with _progress(sum(p.stat().st_size for p in files), progress) as bar:
        if mcap_files:
            _feed_mcap(ingest, mcap_files, timeline, bar)
        for path in other:
            _feed_foreign(ingest, path, bar)
    ingest.finish_streams()
    try:
        frame, summary = build_table(ingest)
    except LogError as exc:
        damage = "; ".join(f"{Path(r.path).name}: {r.warning()}" for r in timeline.reports if r.warning())
        raise LogError(f"{exc}" + (f" ({damage})" if damage else "")) from None
    warnings = [w for w in (r.warning() for r in timeline.reports) if w]
    if "imu-scale" in ingest.notes:
        warnings.append("IMU channel metadata has no accel_scale_mps2_per_lsb: accel_x/y/z_mps2 left out")
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


def _feed_mcap(ingest: Ingest, files: list[Path], timeline: Timeline, bar) -> None:
    done = 0
    for index, offset, window in iter_log_windows(files, timeline):
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


def read_logs(paths, rate_hz: float = 10.0, dbc: str | Path | None = None, progress: bool = False) -> pd.DataFrame:
    """The signals table of logs (columns of `analysis.signals`; absent sources, absent columns).

    The summary is in ``frame.attrs["ingest"]``.
    """
    frame, summary = ingest_logs(paths, rate_hz=rate_hz, dbc=dbc, progress=progress)
    frame.attrs["ingest"] = summary
    return frame


def stage(ctx) -> None:
    """Pipeline stage: ``ctx.inputs`` → ``ctx.signals`` and ``ctx.summary["ingest"]``.

    Options (``ctx.options["ingest"]``): ``rate_hz`` (10), ``dbc`` (a DBC file for further signals), ``progress``.
    """
    options = ctx.options.get("ingest", {})
    frame, summary = ingest_logs(ctx.inputs, rate_hz=float(options.get("rate_hz", 10.0)),
                                 dbc=options.get("dbc"), progress=bool(options.get("progress", False)),
                                 say=ctx.say)
    if "speed_mps" not in frame.columns:
        raise UserError("the logs hold no vehicle speed (neither J1939 CCVS1 wheel-based speed nor OBD-II "
                        "PID 0x0D): log the vehicle's CAN bus, or give a signals table with speed_mps")
    ctx.signals = frame
    ctx.summary["ingest"] = summary
    if "rate_hz" in summary:
        ctx.say(f"ingest: {summary['rows']} rows at {summary['rate_hz']:g} Hz, "
                f"{summary['valid_fraction']:.0%} valid, {summary['can_frames']} CAN frames")
    else:
        ctx.say(f"ingest: signals table, {summary['rows']} rows")
