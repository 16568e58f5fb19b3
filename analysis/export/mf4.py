"""ASAM MDF 4 (``.mf4``) as a CANedge writes it, through asammdf: the CAN bus-logging groups
``CAN_DataFrame`` and ``CAN_RemoteFrame`` (structure channels with ``BusChannel``, ``ID``, ``IDE``,
``DLC``, ``DataLength``, ``DataBytes``, ``Dir``; channel group flagged as bus event, acquisition
source of bus type CAN, the layout python-can's ``MF4Writer`` writes), and the decoded signals table
as one group of channels with their units. asammdf's bus-logging functions (``extract_bus_logging``
with a DBC) and the asammdf GUI read it as they read a CANedge file.
"""

from __future__ import annotations

from datetime import datetime, timezone

import numpy as np

from haulprofile.contract import CAN_FLAG_ERROR, CAN_FLAG_EXTENDED, CAN_FLAG_REMOTE, CAN_FLAG_TX

from ..units import unit_of
from .source import NS_PER_S, LogContent

BLOCK_FRAMES = 1 << 20
"""Frames handed to asammdf per ``extend`` (bounds the copy held beside the log)."""
DATA_DTYPE = np.dtype([
    ("CAN_DataFrame.BusChannel", "<u1"),
    ("CAN_DataFrame.ID", "<u4"),
    ("CAN_DataFrame.IDE", "<u1"),
    ("CAN_DataFrame.DLC", "<u1"),
    ("CAN_DataFrame.DataLength", "<u1"),
    ("CAN_DataFrame.DataBytes", "(8,)u1"),
    ("CAN_DataFrame.Dir", "<u1"),
])
REMOTE_DTYPE = np.dtype([
    ("CAN_RemoteFrame.BusChannel", "<u1"),
    ("CAN_RemoteFrame.ID", "<u4"),
    ("CAN_RemoteFrame.IDE", "<u1"),
    ("CAN_RemoteFrame.DLC", "<u1"),
    ("CAN_RemoteFrame.DataLength", "<u1"),
    ("CAN_RemoteFrame.Dir", "<u1"),
])


def bus_records(frames: np.ndarray, dtype: np.dtype) -> np.ndarray:
    """CAN records (contract dtype) as MDF bus-logging records of ``dtype``."""
    prefix = dtype.names[0].split(".")[0]
    out = np.zeros(len(frames), dtype)
    out[f"{prefix}.BusChannel"] = frames["channel"]
    out[f"{prefix}.ID"] = frames["arbitration_id"]
    out[f"{prefix}.IDE"] = (frames["flags"] & CAN_FLAG_EXTENDED) != 0
    out[f"{prefix}.DLC"] = frames["dlc"]
    out[f"{prefix}.Dir"] = (frames["flags"] & CAN_FLAG_TX) != 0
    if f"{prefix}.DataBytes" in dtype.names:
        out[f"{prefix}.DataLength"] = frames["dlc"]
        out[f"{prefix}.DataBytes"] = frames["data"]
    return out


def _bus_source():
    from asammdf import Source
    from asammdf.blocks.v4_constants import BUS_TYPE_CAN, SOURCE_BUS

    return Source(name="CAN", path="CAN", comment="", source_type=SOURCE_BUS, bus_type=BUS_TYPE_CAN)


class Mf4Writer:
    """An MF4 written as frames come (a window of a log at a time): times relative to the whole
    second before ``first_ns`` (else the first frame), the header's start time (that second on the
    exported clock) set at `finish`, when the log's clock offset is known. A decoded row earlier
    than that second gets a negative time (MDF allows it)."""

    def __init__(self, first_ns: int | None = None):
        from asammdf import MDF

        self.mdf = MDF(version="4.11")
        self.origin_ns: int | None = None if first_ns is None else int(first_ns) - int(first_ns) % NS_PER_S
        """The whole second before the first sample, on the log's own clock [ns]."""
        self.groups: dict[str, int] = {}
        self.frames = 0

    def add(self, frames: np.ndarray) -> None:
        """CAN records (contract dtype, the log's own clock); error frames are left out."""
        frames = frames[(frames["flags"] & CAN_FLAG_ERROR) == 0]
        if len(frames) == 0:
            return
        if self.origin_ns is None:
            first = int(frames["t_mono_ns"].min())
            self.origin_ns = first - first % NS_PER_S
        remote = (frames["flags"] & CAN_FLAG_REMOTE) != 0
        for first in range(0, len(frames), BLOCK_FRAMES):
            block, block_remote = frames[first:first + BLOCK_FRAMES], remote[first:first + BLOCK_FRAMES]
            self._append("CAN_DataFrame", block[~block_remote], DATA_DTYPE)
            self._append("CAN_RemoteFrame", block[block_remote], REMOTE_DTYPE)
        self.frames += len(frames)

    def _append(self, name: str, frames: np.ndarray, dtype: np.dtype) -> None:
        from asammdf import Signal

        if len(frames) == 0:
            return
        seconds = (frames["t_mono_ns"].astype(np.int64) - self.origin_ns) / 1e9
        records = bus_records(frames, dtype)
        if name not in self.groups:
            source = _bus_source()
            self.groups[name] = self.mdf.append(Signal(records, seconds, name=name, source=source), acq_name=name,
                                                acq_source=source, comment="haulprofile export")
        else:
            self.mdf.extend(self.groups[name], [(seconds, None), (records, None)])

    def finish(self, target, wall_offset_ns: int, table=None, row_mono_ns=None) -> None:
        """Append the decoded ``table`` (rows at ``row_mono_ns`` [ns], the log's clock), set the
        start time (``wall_offset_ns``: whole seconds) and save to ``target`` (a path)."""
        try:
            if self.origin_ns is None:
                first = int(row_mono_ns[0]) if row_mono_ns is not None and len(row_mono_ns) else 0
                self.origin_ns = first - first % NS_PER_S
            if table is not None and len(table):
                _append_signals(self.mdf, table, np.asarray(row_mono_ns, np.int64), self.origin_ns)
            start_s = (self.origin_ns + wall_offset_ns) // NS_PER_S
            self.mdf.header.start_time = datetime.fromtimestamp(start_s, timezone.utc)
            self.mdf.save(target, overwrite=False, compression=2)
        finally:
            self.mdf.close()


def _append_signals(mdf, table, row_mono_ns: np.ndarray, origin_ns: int) -> None:
    from asammdf import Signal

    seconds = (row_mono_ns - origin_ns) / 1e9
    known = table.attrs.get("units", {})
    signals = []
    for column in table.columns:
        if column in ("time_s", "wall_time_ns"):
            continue
        values = table[column].to_numpy()
        if values.dtype == bool:
            values = values.astype(np.uint8)
        if values.dtype.kind not in "iuf":
            continue
        signals.append(Signal(values, seconds, name=str(column), unit=unit_of(str(column), known),
                              comment="decoded by haulprofile"))
    if signals:
        mdf.append(signals, acq_name="haulprofile signals", comment="decoded signals table, SI units")


def write(content: LogContent, target, table=None, row_mono_ns=None) -> None:
    """Write ``content`` (and the decoded ``table``, rows at ``row_mono_ns`` [ns]) as MF4 to ``target``."""
    firsts = [int(content.frames["t_mono_ns"].min())] if len(content.frames) else []
    if row_mono_ns is not None and len(row_mono_ns):
        firsts.append(int(row_mono_ns[0]))
    writer = Mf4Writer(min(firsts) if firsts else None)
    writer.add(content.frames)
    writer.finish(target, content.wall_offset_ns, table, row_mono_ns)
