"""Vectorised SAE J1939 decoding of raw CAN record arrays (contract dtype), and TP reassembly.

Frames are grouped by PGN with NumPy masks; each SPN is one shift-and-mask over the 8 data bytes
read as a little-endian uint64 (J1939-71 byte/bit layout from `haulprofile.contract.j1939.SPNS`). Raw values
above the SPN's largest valid value ("error" and "not available" indicators) become NaN.
Source addresses are kept: every decoded array carries the sender's address.

Transport protocol (J1939-21): BAM and RTS/CTS sessions are reassembled from TP.CM/TP.DT frames
(few, so a plain loop), per (source, destination) connection.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from haulprofile.contract import j1939
from haulprofile.contract import CAN_FLAG_ERROR, CAN_FLAG_EXTENDED, CAN_FLAG_REMOTE

from . import frame_kernels

TP_PGNS = (j1939.PGN_TP_CM, j1939.PGN_TP_DT)


def data_u64(frames: np.ndarray) -> np.ndarray:
    """The 8 data bytes of each frame as one little-endian uint64."""
    return np.ascontiguousarray(frames["data"]).view("<u8").ravel()


def pgn_and_source(arbitration_id: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """PGN (destination cleared for PDU1) and source address of 29-bit identifiers."""
    ids = arbitration_id.astype(np.uint32, copy=False)
    pgn = (ids >> 8) & 0x3FFFF
    pdu1 = ((pgn >> 8) & 0xFF) < 240
    pgn = np.where(pdu1, pgn & 0x3FF00, pgn)
    return pgn, (ids & 0xFF).astype(np.uint8)


def j1939_frames(frames: np.ndarray) -> np.ndarray:
    """Mask of extended data frames (neither remote nor error frames)."""
    flags = frames["flags"]
    return ((flags & CAN_FLAG_EXTENDED) != 0) & ((flags & (CAN_FLAG_REMOTE | CAN_FLAG_ERROR)) == 0)


def spn_values(spn: j1939.Spn, data: np.ndarray) -> np.ndarray:
    """Physical values of ``spn`` from uint64 data words [SPN unit]; NaN where error/not available."""
    raw = (data >> np.uint64(spn.bit_offset)) & np.uint64((1 << spn.length_bits) - 1)
    values = raw.astype(np.float64) * spn.resolution + spn.offset
    values[raw > spn.max_valid_raw] = np.nan
    return values


@dataclass
class DecodedPgn:
    """The frames of one PGN and their SPN values, in frame order."""

    pgn: int
    time_ns: np.ndarray
    source: np.ndarray
    values: dict[str, np.ndarray]


class FrameColumns:
    """A block of frames as the decoders share it: its records as words (`frame_kernels.frame_words`),
    and the frames of each of `GROUPED_PGNS` (extended data frames only) and the possible OBD-II
    frames, in frame order (`frames_of`, `obd_candidates`)."""

    def __init__(self, frames: np.ndarray):
        self.frames = frames
        self.words3 = frame_kernels.frame_words(frames)
        self.grouped, self.group_starts = frame_kernels.group_frames(self.words3, _GROUP_CODES, len(GROUPED_PGNS))

    @classmethod
    def of(cls, frames: np.ndarray) -> "FrameColumns":
        return cls(frames)

    @property
    def time_ns(self) -> np.ndarray:
        return self.words3[:, 0].view(np.int64)

    @property
    def words(self) -> np.ndarray:
        """The 8 data bytes of each frame as one little-endian uint64."""
        return self.words3[:, 2]

    def frames_of(self, pgn: int) -> np.ndarray:
        """Indices of the extended data frames of ``pgn``, ascending."""
        k = _GROUP_INDEX.get(pgn)
        if k is None:
            pgns, _ = pgn_and_source(self.frames["arbitration_id"])
            return np.flatnonzero(j1939_frames(self.frames) & (pgns == pgn))
        return self.grouped[self.group_starts[k]:self.group_starts[k + 1]]

    def obd_candidates(self) -> np.ndarray:
        """Indices of frames with an OBD-II request or response identifier (any flags), ascending."""
        k = len(GROUPED_PGNS)
        return self.grouped[self.group_starts[k]:self.group_starts[k + 1]]


SINGLE_FRAME_PGNS = tuple(sorted({s.pgn for s in j1939.SPNS.values()} - set(j1939.PGN_LENGTH)))
GROUPED_PGNS = SINGLE_FRAME_PGNS + TP_PGNS
_GROUP_INDEX = {pgn: k for k, pgn in enumerate(GROUPED_PGNS)}
_GROUP_CODES = frame_kernels.pgn_codes(GROUPED_PGNS)


def decode_block(frames: np.ndarray, pgns=SINGLE_FRAME_PGNS, columns: FrameColumns | None = None
                 ) -> dict[int, DecodedPgn]:
    """Decode every single-frame PGN of ``pgns`` (default: all in `haulprofile.contract.j1939.SPNS`) in ``frames``."""
    c = columns if columns is not None else FrameColumns.of(frames)
    out = {}
    for number in pgns:
        index = c.frames_of(number)
        if len(index) == 0:
            continue
        time_ns, sources, words = frame_kernels.gather(c.words3, index)
        values = {s.name: spn_values(s, words) for s in j1939.spns_of(number)
                  if s.bit_offset + s.length_bits <= 64}
        out[number] = DecodedPgn(number, time_ns, sources, values)
    return out


def tp_frames(frames: np.ndarray, columns: FrameColumns | None = None) -> np.ndarray:
    """The TP.CM and TP.DT frames of a block (kept for reassembly after all blocks are read)."""
    c = columns if columns is not None else FrameColumns.of(frames)
    return frames[np.union1d(c.frames_of(TP_PGNS[0]), c.frames_of(TP_PGNS[1]))]


@dataclass(frozen=True)
class TpMessage:
    """One reassembled multi-packet message."""

    time_ns: int
    pgn: int
    source: int
    destination: int
    data: bytes


@dataclass
class TpStats:
    bam: int = 0
    rts_cts: int = 0
    incomplete: int = 0
    aborted: int = 0


class _Session:
    __slots__ = ("pgn", "size", "packets", "parts", "kind")

    def __init__(self, pgn: int, size: int, packets: int, kind: str):
        self.pgn, self.size, self.packets, self.kind = pgn, size, packets, kind
        self.parts: dict[int, bytes] = {}


def _tp_columns(frames: np.ndarray) -> tuple[list[int], list[int], list[int], list[int], list[bytes]]:
    """(time [ns], PDU format, destination, source, the data bytes the DLC gives, padded with 0xFF
    to 8) of each frame, as Python values: the reassembly's loop then touches no NumPy scalar."""
    ids = frames["arbitration_id"].astype(np.int64)
    width = frames.dtype["data"].itemsize
    raw = np.ascontiguousarray(frames["data"]).tobytes()
    payloads = []
    for k, dlc in enumerate(frames["dlc"].tolist()):
        data = raw[k * width:k * width + min(dlc, width)]
        payloads.append(data if len(data) >= 8 else data.ljust(8, b"\xff"))
    return (frames["t_mono_ns"].tolist(), ((ids >> 16) & 0xFF).tolist(), ((ids >> 8) & 0xFF).tolist(),
            (ids & 0xFF).tolist(), payloads)


def reassemble(frames: np.ndarray) -> tuple[list[TpMessage], TpStats]:
    """Multi-packet messages of BAM and RTS/CTS sessions in time-sorted TP frames (J1939-21)."""
    stats = TpStats()
    messages: list[TpMessage] = []
    if len(frames) == 0:
        return messages, stats
    frames = frames[np.argsort(frames["t_mono_ns"], kind="stable")]
    times, pf, destination, source, payloads = _tp_columns(frames)
    sessions: dict[tuple[int, int], _Session] = {}
    for k in range(len(frames)):
        data = payloads[k]
        sa, da = source[k], destination[k]
        if pf[k] == j1939.PGN_TP_CM >> 8:
            control = data[0]
            pgn = int.from_bytes(data[5:8], "little")
            if control in (j1939.TP_CM_BAM, j1939.TP_CM_RTS):
                if (sa, da) in sessions:
                    stats.incomplete += 1
                size = data[1] | (data[2] << 8)
                packets = data[3]
                if packets == 0 or size > 1785 or (size + 6) // 7 != packets:
                    sessions.pop((sa, da), None)
                    continue
                kind = "bam" if control == j1939.TP_CM_BAM else "rts"
                sessions[(sa, da)] = _Session(pgn, size, packets, kind)
            elif control == j1939.TP_CM_ABORT:
                # An abort comes from either end of the connection.
                for key in ((sa, da), (da, sa)):
                    if key in sessions:
                        sessions.pop(key)
                        stats.aborted += 1
        elif pf[k] == j1939.PGN_TP_DT >> 8:
            session = sessions.get((sa, da))
            if session is None:
                continue
            sequence = data[0]
            if 1 <= sequence <= session.packets:
                session.parts[sequence] = data[1:8]
            if len(session.parts) == session.packets:
                payload = b"".join(session.parts[i] for i in range(1, session.packets + 1))[:session.size]
                messages.append(TpMessage(times[k], session.pgn, sa, da, payload))
                if session.kind == "bam":
                    stats.bam += 1
                else:
                    stats.rts_cts += 1
                del sessions[(sa, da)]
    stats.incomplete += len(sessions)
    return messages, stats


def decode_tp(messages: list[TpMessage]) -> dict[int, DecodedPgn]:
    """SPN values of reassembled messages, per PGN (scalar reference decoder; few messages)."""
    grouped: dict[int, list[TpMessage]] = {}
    for message in messages:
        if j1939.spns_of(message.pgn):
            grouped.setdefault(message.pgn, []).append(message)
    out = {}
    for pgn, group in grouped.items():
        decoded = [j1939.decode_pgn(pgn, m.data) for m in group]
        names = sorted({name for d in decoded for name in d})
        values = {n: np.array([np.nan if d.get(n) is None else d[n] for d in decoded]) for n in names}
        out[pgn] = DecodedPgn(pgn, np.array([m.time_ns for m in group], dtype=np.int64),
                              np.array([m.source for m in group], dtype=np.uint8), values)
    return out
