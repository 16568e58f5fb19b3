"""OBD-II mode 01 (SAE J1979) over ISO 15765-4: identifiers and the PIDs the project polls.

Shared by the poller and ECU emulator (encode) and the analysis (decode); formulas from J1979.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

FUNCTIONAL_REQUEST_ID_11BIT = 0x7DF
RESPONSE_IDS_11BIT = range(0x7E8, 0x7F0)
FUNCTIONAL_REQUEST_ID_29BIT = 0x18DB33F1
RESPONSE_ID_29BIT_BASE = 0x18DAF100   # | ECU address
SERVICE_CURRENT_DATA = 0x01
POSITIVE_RESPONSE_OFFSET = 0x40
PAD_BYTE = 0x55


@dataclass(frozen=True)
class Pid:
    pid: int
    name: str
    n_bytes: int
    unit: str
    decode: Callable[[list[int]], float]
    encode: Callable[[float], list[int]]


def _u16(value: float, scale: float) -> list[int]:
    raw = min(max(int(round(value * scale)), 0), 0xFFFF)
    return [raw >> 8, raw & 0xFF]


PIDS: dict[int, Pid] = {p.pid: p for p in (
    Pid(0x0C, "engine_speed_rpm", 2, "rpm", lambda b: (256 * b[0] + b[1]) / 4.0, lambda v: _u16(v, 4.0)),
    Pid(0x0D, "vehicle_speed_kmh", 1, "km/h", lambda b: float(b[0]), lambda v: [min(max(int(round(v)), 0), 255)]),
    Pid(0x33, "barometric_pressure_kpa", 1, "kPa", lambda b: float(b[0]), lambda v: [min(max(int(round(v)), 0), 255)]),
    Pid(0x46, "ambient_air_temperature_c", 1, "degC", lambda b: b[0] - 40.0,
        lambda v: [min(max(int(round(v + 40)), 0), 255)]),
    Pid(0x61, "driver_demand_torque_pct", 1, "%", lambda b: b[0] - 125.0,
        lambda v: [min(max(int(round(v + 125)), 0), 255)]),
    Pid(0x62, "actual_engine_torque_pct", 1, "%", lambda b: b[0] - 125.0,
        lambda v: [min(max(int(round(v + 125)), 0), 255)]),
    Pid(0x63, "engine_reference_torque_nm", 2, "Nm", lambda b: float(256 * b[0] + b[1]), lambda v: _u16(v, 1.0)),
)}

DEFAULT_POLL_PIDS = (0x0D, 0x0C, 0x62, 0x63, 0x61, 0x33, 0x46)


def request_frame(pid: int) -> bytes:
    """ISO-TP single frame of a mode 01 request, padded to 8 bytes."""
    return bytes([2, SERVICE_CURRENT_DATA, pid]).ljust(8, bytes([PAD_BYTE]))


def response_frame(pid: int, value: float) -> bytes:
    """ISO-TP single frame of the positive response carrying ``value``."""
    payload = [SERVICE_CURRENT_DATA + POSITIVE_RESPONSE_OFFSET, pid, *PIDS[pid].encode(value)]
    return bytes([len(payload), *payload]).ljust(8, bytes([PAD_BYTE]))
