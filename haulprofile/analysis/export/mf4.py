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


def _append_frames(mdf, name: str, frames: np.ndarray, dtype: np.dtype, start_ns: int) -> None:
    from asammdf import Signal

    if len(frames) == 0:
        return
    source = _bus_source()
    group = None
    for first in range(0, len(frames), BLOCK_FRAMES):
        block = frames[first:first + BLOCK_FRAMES]
        seconds = (block["t_mono_ns"].astype(np.int64) - start_ns) / 1e9
        records = bus_records(block, dtype)
        if group is None:
            group = mdf.append(Signal(records, seconds, name=name, source=source), acq_name=name, acq_source=source,
                               comment="haulprofile export")
        else:
            mdf.extend(group, [(seconds, None), (records, None)])


def _append_signals(mdf, table, row_mono_ns: np.ndarray, start_ns: int) -> None:
    from asammdf import Signal

    seconds = (row_mono_ns - start_ns) / 1e9
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
    """Write ``content`` (and the decoded ``table``, rows at ``row_mono_ns`` [ns]) as MF4 to ``target``
    (a path or a binary file object)."""
    from asammdf import MDF

    frames = content.frames[(content.frames["flags"] & CAN_FLAG_ERROR) == 0].copy()
    frames["t_mono_ns"] = content.times_ns(frames["t_mono_ns"]).astype(np.uint64)
    first = [int(frames["t_mono_ns"][0])] if len(frames) else []
    if row_mono_ns is not None and len(row_mono_ns):
        first.append(int(content.times_ns(row_mono_ns[:1])[0]))
    start_ns = min(first) if first else 0
    start_ns -= start_ns % NS_PER_S
    mdf = MDF(version="4.11")
    mdf.header.start_time = datetime.fromtimestamp(start_ns // NS_PER_S, timezone.utc)
    try:
        remote = (frames["flags"] & CAN_FLAG_REMOTE) != 0
        _append_frames(mdf, "CAN_DataFrame", frames[~remote], DATA_DTYPE, start_ns)
        _append_frames(mdf, "CAN_RemoteFrame", frames[remote], REMOTE_DTYPE, start_ns)
        if table is not None:
            _append_signals(mdf, table, content.times_ns(row_mono_ns), start_ns)
        mdf.save(target, overwrite=False, compression=2)
    finally:
        mdf.close()
