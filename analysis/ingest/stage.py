"""The ingest stage: logs (or other loggers' CAN logs) → the signals table of aligned measured
columns, in memory; kinematics adds distance and acceleration after it."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..errors import UserError
from ..stage import Stage
from . import ingest_logs


@dataclass(frozen=True)
class IngestOptions:
    """Options of the ingest stage."""

    rate_hz: float = 10.0
    """Rate of the signals table [Hz]."""
    dbc: Path | None = None
    """A DBC file whose signals are decoded as further columns."""
    progress: bool = False
    """A progress bar on stderr."""


@dataclass
class IngestResult:
    """What the ingest read: rows, rate, gaps, CAN frames, sources chosen per column, notes."""

    report: dict

    def summary(self) -> dict:
        return self.report


def ingest_stage(ctx) -> IngestResult:
    """Read ``ctx.inputs`` into ``ctx.signals``.

    Parameters
    ----------
    ctx : pipeline.RunContext
        Reads ``inputs`` (MCAP logs, directories of them, other loggers' CAN logs) and
        ``options.ingest`` (`IngestOptions`: ``rate_hz`` [Hz], ``dbc``).
    """
    options: IngestOptions = ctx.options.ingest
    frame, summary = ingest_logs(ctx.inputs, rate_hz=float(options.rate_hz), dbc=options.dbc,
                                 progress=bool(options.progress), say=ctx.say)
    if "speed_mps" not in frame.columns:
        raise UserError("the logs hold no vehicle speed (neither J1939 CCVS1 wheel-based speed nor OBD-II "
                        "PID 0x0D nor GPS speed): log the vehicle's CAN bus, or give a signals table with speed_mps")
    ctx.signals = frame
    if "can_frames" in summary:
        ctx.say(f"ingest: {summary['rows']} rows at {summary['rate_hz']:g} Hz, "
                f"{summary['valid_fraction']:.0%} valid, {summary['can_frames']} CAN frames")
    else:
        ctx.say(f"ingest: signals table, {summary['rows']} rows")
    return IngestResult(summary)


STAGE = Stage("ingest", IngestOptions, ingest_stage, needs_signals=False)
