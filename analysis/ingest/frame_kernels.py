"""One pass over a block of raw CAN records: the frames of each wanted J1939 PGN, and the possible
OBD-II frames, grouped (a counting sort, in frame order), instead of NumPy masks over the whole
block per PGN."""

from __future__ import annotations

import numba
import numpy as np

from haulprofile.contract import CAN_FLAG_ERROR, CAN_FLAG_EXTENDED, CAN_FLAG_REMOTE

PGN_SPACE = 1 << 18


def pgn_codes(pgns) -> np.ndarray:
    """Lookup table PGN → its position in ``pgns`` (-1 for every other PGN)."""
    if len(pgns) > 126:
        raise ValueError("at most 126 grouped PGNs (codes are int8)")
    table = np.full(PGN_SPACE, -1, np.int8)
    table[np.asarray(pgns, dtype=np.int64)] = np.arange(len(pgns), dtype=np.int8)
    return table


def frame_words(frames: np.ndarray) -> np.ndarray:
    """Raw CAN records (contract dtype) as n × 3 little-endian uint64: time; identifier, flags,
    dlc, channel; the 8 data bytes."""
    return np.ascontiguousarray(frames).view(np.uint64).reshape(len(frames), 3)


@numba.njit(cache=True, nogil=True, inline="always")
def _code(head, codes, n_codes):
    """Group of one record (its identifier-and-flags word): the PGN's code for extended data frames
    of a wanted PGN, ``n_codes`` for a possible OBD-II request or response, else -1. Written
    without branches: which frame comes next on a bus is a coin toss for the branch predictor."""
    arbitration_id = np.uint32(head & np.uint64(0xFFFFFFFF))
    f = np.uint32((head >> np.uint64(32)) & np.uint64(0xFF))
    extended_data = ((f & np.uint32(CAN_FLAG_EXTENDED)) != 0) & \
        ((f & np.uint32(CAN_FLAG_REMOTE | CAN_FLAG_ERROR)) == 0)
    p = (arbitration_id >> np.uint32(8)) & np.uint32(0x3FFFF)
    pdu1 = ((p >> np.uint32(8)) & np.uint32(0xFF)) < np.uint32(240)
    p = p & (np.uint32(0x3FF00) if pdu1 else np.uint32(0x3FFFF))
    c = np.int64(codes[p])
    obd = ((arbitration_id >= np.uint32(0x7DF)) & (arbitration_id <= np.uint32(0x7EF))) | \
        ((arbitration_id >> np.uint32(17)) == np.uint32(0x18DA0000 >> 17))
    other = np.int64(n_codes) if obd else np.int64(-1)
    return c if (extended_data & (c >= 0)) else other


@numba.njit(cache=True, nogil=True)
def group_frames(words3, codes, n_codes):
    """Indices of the records (`frame_words`) of each group (`_code`), in frame order: (indices,
    starts of the ``n_codes`` + 1 groups)."""
    n = words3.shape[0]
    code = np.empty(n, np.int8)
    starts = np.zeros(n_codes + 2, np.int64)
    for i in range(n):
        c = _code(words3[i, 1], codes, n_codes)
        code[i] = c
        starts[c + 1] += 1  # -1 (no group) counts into starts[0], cleared below
    starts[0] = 0
    for k in range(n_codes + 1):
        starts[k + 1] += starts[k]
    order = np.empty(starts[n_codes + 1], np.int64)
    fill = starts[:n_codes + 1].copy()
    for i in range(n):
        c = code[i]
        if c >= 0:
            order[fill[c]] = i
            fill[c] += 1
    return order, starts


@numba.njit(cache=True, nogil=True)
def gather(words3, index):
    """Time [ns], source address and data word of the records at ``index``."""
    n = len(index)
    time_ns = np.empty(n, np.int64)
    source = np.empty(n, np.uint8)
    words = np.empty(n, np.uint64)
    for k in range(n):
        i = index[k]
        time_ns[k] = np.int64(words3[i, 0])
        source[k] = np.uint8(words3[i, 1] & np.uint64(0xFF))
        words[k] = words3[i, 2]
    return time_ns, source, words
