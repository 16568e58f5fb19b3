"""SAE J1939 definitions shared by the ECU emulator (encode) and the analysis (vectorised decode).

Identifiers (J1939-21), the transport protocol constants, and the J1939-71 layout of the SPNs the
project uses: start byte and bit (1-based as in the standard), length, resolution, offset.
The logger itself never decodes: it stores frames raw (architecture principle 1).
"""

from __future__ import annotations

from dataclasses import dataclass

PGN_REQUEST = 59904      # 0xEA00
PGN_TP_CM = 60416        # 0xEC00 transport protocol connection management
PGN_TP_DT = 60160        # 0xEB00 transport protocol data transfer
PGN_ADDRESS_CLAIMED = 60928

TP_CM_RTS = 16
TP_CM_CTS = 17
TP_CM_EOM_ACK = 19
TP_CM_BAM = 32
TP_CM_ABORT = 255

GLOBAL_ADDRESS = 0xFF

PGN_EEC1 = 61444   # Electronic Engine Controller 1
PGN_EEC2 = 61443   # Electronic Engine Controller 2
PGN_EEC3 = 65247   # Electronic Engine Controller 3
PGN_ETC2 = 61445   # Electronic Transmission Controller 2
PGN_EBC1 = 61441   # Electronic Brake Controller 1
PGN_CCVS1 = 65265  # Cruise Control/Vehicle Speed 1
PGN_LFE = 65266    # Fuel Economy (Liquid)
PGN_EC1 = 65251    # Engine Configuration 1 (39 bytes: multi-packet)
PGN_VW = 65258     # Vehicle Weight
PGN_CVW = 65136    # Combination Vehicle Weight

PGN_NAMES = {
    PGN_EEC1: "EEC1", PGN_EEC2: "EEC2", PGN_EEC3: "EEC3", PGN_ETC2: "ETC2", PGN_EBC1: "EBC1", PGN_CCVS1: "CCVS1",
    PGN_LFE: "LFE", PGN_EC1: "EC1", PGN_VW: "VW", PGN_CVW: "CVW", PGN_REQUEST: "RQST",
    PGN_TP_CM: "TP.CM", PGN_TP_DT: "TP.DT",
}


@dataclass(frozen=True)
class Spn:
    """Layout of one suspect parameter in a PGN's data (J1939-71)."""

    spn: int
    name: str
    pgn: int
    start_byte: int      # 1-based
    start_bit: int       # 1-based within the start byte
    length_bits: int
    resolution: float
    offset: float
    unit: str

    @property
    def bit_offset(self) -> int:
        """Little-endian bit position of the first bit (0-based across the data)."""
        return (self.start_byte - 1) * 8 + (self.start_bit - 1)

    @property
    def max_valid_raw(self) -> int:
        """Largest raw value that is data; above it are error and not-available indicators."""
        if self.length_bits == 1:
            return 1
        if self.length_bits == 2:
            return 1
        if self.length_bits == 4:
            return 0xA
        if self.length_bits == 8:
            return 0xFA
        if self.length_bits == 16:
            return 0xFAFF
        if self.length_bits == 32:
            return 0xFAFFFFFF
        return (1 << self.length_bits) - 1 - 5

    @property
    def not_available_raw(self) -> int:
        return (1 << self.length_bits) - 1

    def encode_raw(self, value: float | None) -> int:
        """Raw bits for a physical value; None (or NaN) is sent as "not available"."""
        if value is None or value != value:
            return self.not_available_raw
        raw = int(round((value - self.offset) / self.resolution))
        return min(max(raw, 0), self.max_valid_raw)

    def decode_raw(self, raw: int) -> float | None:
        if raw > self.max_valid_raw:
            return None
        return raw * self.resolution + self.offset


SPNS: dict[str, Spn] = {s.name: s for s in (
    Spn(512, "driver_demand_torque_pct", PGN_EEC1, 2, 1, 8, 1.0, -125.0, "%"),
    Spn(513, "actual_engine_torque_pct", PGN_EEC1, 3, 1, 8, 1.0, -125.0, "%"),
    Spn(190, "engine_speed_rpm", PGN_EEC1, 4, 1, 16, 0.125, 0.0, "rpm"),
    Spn(514, "nominal_friction_torque_pct", PGN_EEC3, 1, 1, 8, 1.0, -125.0, "%"),
    Spn(2978, "parasitic_loss_torque_pct", PGN_EEC3, 5, 1, 8, 1.0, -125.0, "%"),
    Spn(91, "accelerator_pedal_pct", PGN_EEC2, 2, 1, 8, 0.4, 0.0, "%"),
    Spn(92, "engine_load_pct", PGN_EEC2, 3, 1, 8, 1.0, 0.0, "%"),
    Spn(524, "selected_gear", PGN_ETC2, 1, 1, 8, 1.0, -125.0, ""),
    Spn(526, "actual_gear_ratio", PGN_ETC2, 2, 1, 16, 0.001, 0.0, ""),
    Spn(523, "current_gear", PGN_ETC2, 4, 1, 8, 1.0, -125.0, ""),
    Spn(521, "brake_pedal_pct", PGN_EBC1, 2, 1, 8, 0.4, 0.0, "%"),
    Spn(84, "wheel_speed_kmh", PGN_CCVS1, 2, 1, 16, 1.0 / 256.0, 0.0, "km/h"),
    Spn(597, "brake_switch", PGN_CCVS1, 4, 5, 2, 1.0, 0.0, ""),
    Spn(598, "clutch_switch", PGN_CCVS1, 4, 7, 2, 1.0, 0.0, ""),
    Spn(183, "fuel_rate_lph", PGN_LFE, 1, 1, 16, 0.05, 0.0, "L/h"),
    Spn(544, "engine_reference_torque_nm", PGN_EC1, 20, 1, 16, 1.0, 0.0, "Nm"),
    Spn(928, "axle_location", PGN_VW, 1, 1, 8, 1.0, 0.0, ""),
    Spn(582, "axle_weight_kg", PGN_VW, 2, 1, 16, 0.5, 0.0, "kg"),
    Spn(180, "trailer_weight_kg", PGN_VW, 4, 1, 16, 2.0, 0.0, "kg"),
    Spn(181, "cargo_weight_kg", PGN_VW, 6, 1, 16, 2.0, 0.0, "kg"),
    Spn(1759, "powered_vehicle_weight_kg", PGN_CVW, 1, 1, 16, 10.0, 0.0, "kg"),
    Spn(1760, "gross_combination_weight_kg", PGN_CVW, 3, 1, 16, 10.0, 0.0, "kg"),
)}

PGN_LENGTH = {PGN_EC1: 39}
"""Data length of PGNs longer than 8 bytes (sent with the transport protocol)."""


def spns_of(pgn: int) -> list[Spn]:
    return [s for s in SPNS.values() if s.pgn == pgn]


def make_id(pgn: int, source_address: int, priority: int = 6, destination: int = GLOBAL_ADDRESS) -> int:
    """29-bit identifier; for PDU1 PGNs (PF < 240) the destination goes into PS."""
    pf = (pgn >> 8) & 0xFF
    if pf < 240:
        pgn = (pgn & 0x3FF00) | (destination & 0xFF)
    return ((priority & 0x7) << 26) | ((pgn & 0x3FFFF) << 8) | (source_address & 0xFF)


def parse_id(arbitration_id: int) -> tuple[int, int, int, int]:
    """(priority, pgn, source_address, destination) of a 29-bit identifier."""
    priority = (arbitration_id >> 26) & 0x7
    pgn = (arbitration_id >> 8) & 0x3FFFF
    source = arbitration_id & 0xFF
    if ((pgn >> 8) & 0xFF) < 240:
        destination = pgn & 0xFF
        pgn &= 0x3FF00
    else:
        destination = GLOBAL_ADDRESS
    return priority, pgn, source, destination


def encode_pgn(pgn: int, values: dict[str, float | None]) -> bytes:
    """Data bytes of a PGN from physical SPN values; unnamed bits are 1 (not available)."""
    length = PGN_LENGTH.get(pgn, 8)
    bits = (1 << (8 * length)) - 1
    for spn in spns_of(pgn):
        if spn.name in values:
            mask = ((1 << spn.length_bits) - 1) << spn.bit_offset
            bits = (bits & ~mask) | (spn.encode_raw(values[spn.name]) << spn.bit_offset)
    return bits.to_bytes(length, "little")


def decode_pgn(pgn: int, data: bytes) -> dict[str, float | None]:
    """Physical SPN values of one PGN's data (scalar reference for the vectorised decoder)."""
    bits = int.from_bytes(data, "little")
    out = {}
    for spn in spns_of(pgn):
        if spn.bit_offset + spn.length_bits > 8 * len(data):
            continue
        out[spn.name] = spn.decode_raw((bits >> spn.bit_offset) & ((1 << spn.length_bits) - 1))
    return out


def request_data(pgn: int) -> bytes:
    """Data of a PGN 59904 request for ``pgn`` (3 bytes, little-endian)."""
    return pgn.to_bytes(3, "little")


def bam_frames(pgn: int, data: bytes) -> list[bytes]:
    """TP.CM BAM announcement followed by the TP.DT packets carrying ``data`` (J1939-21)."""
    packets = (len(data) + 6) // 7
    cm = bytes([TP_CM_BAM, len(data) & 0xFF, len(data) >> 8, packets, 0xFF]) + pgn.to_bytes(3, "little")
    dts = [bytes([i + 1]) + data[7 * i:7 * i + 7].ljust(7, b"\xff") for i in range(packets)]
    return [cm, *dts]
