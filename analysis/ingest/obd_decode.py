"""OBD-II mode 01 (SAE J1979) responses matched to their requests, vectorised.

A response counts only when a request for the same PID was sent (functional 0x7DF / 0x18DB33F1,
or physical 0x7E0-0x7E7 / 0x18DA..F1) at most `MAX_RESPONSE_DELAY_NS` before it and that ECU has
not answered it yet; unrequested responses are counted. Single-frame ISO-TP payloads only (mode 01 PIDs
fit in one frame).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from haulprofile.contract import obd
from haulprofile.contract import CAN_FLAG_ERROR, CAN_FLAG_EXTENDED, CAN_FLAG_REMOTE

MAX_RESPONSE_DELAY_NS = 1_000_000_000
"""J1979 allows 50 ms (P2); a logger's clock and a busy bus stretch that, so accept up to 1 s."""


def _request_mask(ids: np.ndarray, extended: np.ndarray) -> np.ndarray:
    ids = ids.astype(np.int64)
    eleven = ~extended & ((ids == obd.FUNCTIONAL_REQUEST_ID_11BIT) | ((ids >= 0x7E0) & (ids < 0x7E8)))
    twenty_nine = extended & ((ids == obd.FUNCTIONAL_REQUEST_ID_29BIT) | ((ids & 0x1FFF00FF) == 0x18DA00F1))
    return eleven | twenty_nine


def _response_mask(ids: np.ndarray, extended: np.ndarray) -> np.ndarray:
    ids = ids.astype(np.int64)
    eleven = ~extended & (ids >= 0x7E8) & (ids < 0x7F0)
    twenty_nine = extended & ((ids & 0x1FFFFF00) == obd.RESPONSE_ID_29BIT_BASE)
    return eleven | twenty_nine


def obd_frames(frames: np.ndarray, candidates: np.ndarray | None = None) -> np.ndarray:
    """Mode 01 request and response frames of a block (kept for matching after all blocks);
    ``candidates``: indices of the frames with an OBD-II identifier, if known."""
    if candidates is None:
        ids = frames["arbitration_id"]
        # cheap first cut: 0x7DF-0x7EF, or 29-bit 0x18DA..../0x18DB....
        candidates = np.flatnonzero(((ids >= 0x7DF) & (ids <= 0x7EF)) | ((ids >> 17) == (0x18DA0000 >> 17)))
    frames = frames[candidates]
    flags = frames["flags"]
    data_frame = (flags & (CAN_FLAG_REMOTE | CAN_FLAG_ERROR)) == 0
    extended = (flags & CAN_FLAG_EXTENDED) != 0
    ids = frames["arbitration_id"]
    service = frames["data"][:, 1]
    is_request = _request_mask(ids, extended) & (service == obd.SERVICE_CURRENT_DATA)
    is_response = _response_mask(ids, extended) & (
        service == obd.SERVICE_CURRENT_DATA + obd.POSITIVE_RESPONSE_OFFSET)
    return frames[data_frame & (is_request | is_response)]


@dataclass
class ObdStats:
    requests: int = 0
    responses: int = 0
    matched: int = 0
    unrequested: int = 0


def decode(frames: np.ndarray) -> tuple[dict[str, tuple[np.ndarray, np.ndarray]], ObdStats]:
    """Per PID name: (time [ns], value [PID unit]) of the responses matched to a request."""
    stats = ObdStats()
    out: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    if len(frames) == 0:
        return out, stats
    frames = frames[np.argsort(frames["t_mono_ns"], kind="stable")]
    extended = (frames["flags"] & CAN_FLAG_EXTENDED) != 0
    time = frames["t_mono_ns"].astype(np.int64)
    data = frames["data"]
    is_request = _request_mask(frames["arbitration_id"], extended) & (data[:, 1] == obd.SERVICE_CURRENT_DATA)
    is_response = ~is_request & (data[:, 1] == obd.SERVICE_CURRENT_DATA + obd.POSITIVE_RESPONSE_OFFSET)
    stats.requests, stats.responses = int(is_request.sum()), int(is_response.sum())
    for pid in obd.PIDS.values():
        req_t = time[is_request & (data[:, 2] == pid.pid)]
        resp = is_response & (data[:, 2] == pid.pid) & (data[:, 0] >= 2 + pid.n_bytes)
        resp_t = time[resp]
        if len(resp_t) == 0:
            continue
        before = np.searchsorted(req_t, resp_t, side="right") - 1
        matched = before >= 0
        matched[matched] &= (resp_t[matched] - req_t[before[matched]]) <= MAX_RESPONSE_DELAY_NS
        # each ECU answers a request once: a second answer to the same request is not a match
        pair = before.astype(np.int64) * (1 << 32) + frames["arbitration_id"][resp].astype(np.int64)
        first = np.zeros(len(pair), dtype=bool)
        first[np.unique(pair, return_index=True)[1]] = True
        matched &= first
        stats.matched += int(matched.sum())
        stats.unrequested += int((~matched).sum())
        payload = data[resp][matched, 3:3 + pid.n_bytes].astype(np.float64)
        out[pid.name] = (resp_t[matched], _physical(pid, payload))
    return out, stats


def _physical(pid: obd.Pid, a: np.ndarray) -> np.ndarray:
    """J1979 formulas, vectorised (the scalar ones in `haulprofile.contract.obd.PIDS` are the reference)."""
    if pid.n_bytes == 2:
        raw = 256.0 * a[:, 0] + a[:, 1]
    else:
        raw = a[:, 0]
    scale_offset = {0x0C: (0.25, 0.0), 0x0D: (1.0, 0.0), 0x33: (1.0, 0.0), 0x46: (1.0, -40.0),
                    0x61: (1.0, -125.0), 0x62: (1.0, -125.0), 0x63: (1.0, 0.0)}
    scale, offset = scale_offset[pid.pid]
    return raw * scale + offset
