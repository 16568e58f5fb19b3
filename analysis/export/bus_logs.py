"""Vector BLF and ASC, and candump ``-L`` logs, through python-can's own writers (``BLFWriter``,
``ASCWriter``, ``CanutilsLogWriter``): one ``can.Message`` per frame, flags as python-can defines
them (extended id, remote, error frame, ``is_rx`` False for frames the logger sent).

BLF and ASC store times relative to the first object; a marker at the whole second before the
first frame (a BLF global marker, an ASC event) makes that start a whole second, so times read back
fall in the bins they came from. candump lines carry absolute seconds.
"""

from __future__ import annotations

import numpy as np

from haulprofile.contract import CAN_FLAG_ERROR, CAN_FLAG_EXTENDED, CAN_FLAG_REMOTE, CAN_FLAG_TX

from .source import NS_PER_S, LogContent

MARKER = "haulprofile export"


def messages(frames: np.ndarray, times_ns: np.ndarray, channel_names: bool = False):
    """``can.Message`` of each CAN record at ``times_ns`` [ns]; channels as ints, or ``can<N>``."""
    import can

    flags = frames["flags"]
    for t, ident, flag, dlc, channel, data in zip(times_ns.tolist(), frames["arbitration_id"].tolist(),
                                                  flags.tolist(), frames["dlc"].tolist(),
                                                  frames["channel"].tolist(), map(bytes, frames["data"])):
        remote = bool(flag & CAN_FLAG_REMOTE)
        yield can.Message(timestamp=t / 1e9, arbitration_id=ident, is_extended_id=bool(flag & CAN_FLAG_EXTENDED),
                          is_remote_frame=remote, is_error_frame=bool(flag & CAN_FLAG_ERROR),
                          is_rx=not flag & CAN_FLAG_TX, dlc=dlc, data=b"" if remote else data[:dlc],
                          channel=f"can{channel}" if channel_names else channel, check=False)


def write(content: LogContent, target, kind: str) -> None:
    """Write the frames of ``content`` as ``kind`` (``blf``, ``asc``, ``candump``) to ``target`` (a path)."""
    import can

    frames = content.frames
    times = content.times_ns(frames["t_mono_ns"])
    start_s = (int(times[0]) - int(times[0]) % NS_PER_S) / NS_PER_S if len(times) else 0.0
    if kind == "blf":
        writer = can.BLFWriter(str(target))
    elif kind == "asc":
        writer = _asc_writer(start_s)(str(target))
    else:
        writer = can.CanutilsLogWriter(str(target), channel="can0")
    try:
        if kind in ("blf", "asc") and len(times):
            writer.log_event(MARKER, start_s)
        for message in messages(frames, times, channel_names=kind == "candump"):
            writer.on_message_received(message)
    finally:
        writer.stop()



def _asc_writer(start_s: float):
    """python-can's ``ASCWriter`` whose ``date`` line says when the recording began (its own says
    when the file was written)."""
    from datetime import datetime, timezone

    import can

    start = datetime.fromtimestamp(start_s, timezone.utc).replace(tzinfo=None)

    class AscWriter(can.ASCWriter):
        def _format_header_datetime(self, dt: datetime) -> str:
            return super()._format_header_datetime(start)

    return AscWriter
