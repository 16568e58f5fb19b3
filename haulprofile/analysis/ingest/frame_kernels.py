"""One pass over a block of raw CAN records: the columns every decoder shares, and the frames
of each wanted J1939 PGN grouped (a counting sort, in frame order), instead of one NumPy mask
over the whole block per PGN."""

from __future__ import annotations

import numba
import numpy as np

from haulprofile.contract import CAN_FLAG_ERROR, CAN_FLAG_EXTENDED, CAN_FLAG_REMOTE

PGN_SPACE = 1 << 18


def pgn_codes(pgns) -> np.ndarray:
    """Lookup table PGN → its position in ``pgns`` (-1 for every other PGN)."""
    table = np.full(PGN_SPACE, -1, np.int32)
    table[np.asarray(pgns, dtype=np.int64)] = np.arange(len(pgns), dtype=np.int32)
    return table


def frame_words(frames: np.ndarray) -> np.ndarray:
    """Raw CAN records (contract dtype) as n × 3 little-endian uint64: time; identifier, flags,
    dlc, channel; the 8 data bytes."""
    return np.ascontiguousarray(frames).view(np.uint64).reshape(len(frames), 3)


@numba.njit(cache=True, nogil=True)
def frame_columns(words3, codes, n_codes):
    """(time [ns] int64, PGN (destination cleared for PDU1), source address, extended data frame?,
    data bytes as a little-endian uint64, frame indices grouped by PGN code, group starts) of
    records given as `frame_words`."""
    n = words3.shape[0]
    time_out = np.empty(n, np.int64)
    pgn = np.empty(n, np.uint32)
    source = np.empty(n, np.uint8)
    j1939 = np.empty(n, np.bool_)
    words = np.empty(n, np.uint64)
    code = np.empty(n, np.int32)
    starts = np.zeros(n_codes + 1, np.int64)
    for i in range(n):
        head = words3[i, 1]
        arbitration_id = np.uint32(head & np.uint64(0xFFFFFFFF))
        f = np.uint8((head >> np.uint64(32)) & np.uint64(0xFF))
        p = (arbitration_id >> 8) & 0x3FFFF
        if ((p >> 8) & 0xFF) < 240:
            p &= 0x3FF00
        pgn[i] = p
        source[i] = arbitration_id & 0xFF
        ok = (f & CAN_FLAG_EXTENDED) != 0 and (f & (CAN_FLAG_REMOTE | CAN_FLAG_ERROR)) == 0
        j1939[i] = ok
        words[i] = words3[i, 2]
        time_out[i] = np.int64(words3[i, 0])
        c = codes[p] if ok else -1
        code[i] = c
        if c >= 0:
            starts[c + 1] += 1
    for k in range(n_codes):
        starts[k + 1] += starts[k]
    order = np.empty(starts[n_codes], np.int64)
    fill = starts[:n_codes].copy()
    for i in range(n):
        c = code[i]
        if c >= 0:
            order[fill[c]] = i
            fill[c] += 1
    return time_out, pgn, source, j1939, words, order, starts
