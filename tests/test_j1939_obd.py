"""J1939 and OBD-II encoders against J1939-71/J1979 values written out by hand."""

import pytest

from haulprofile.contract import j1939, obd


def test_eec1_layout():
    data = j1939.encode_pgn(j1939.PGN_EEC1, {"engine_speed_rpm": 1500.0, "actual_engine_torque_pct": 40.0})
    assert len(data) == 8
    assert data[2] == 165                      # 40 % + 125 offset
    assert int.from_bytes(data[3:5], "little") == 12000   # 0.125 rpm/bit
    assert data[1] == 0xFF                     # driver demand not given: not available
    decoded = j1939.decode_pgn(j1939.PGN_EEC1, data)
    assert decoded["engine_speed_rpm"] == 1500.0 and decoded["driver_demand_torque_pct"] is None


def test_ccvs1_speed_and_brake_bits():
    data = j1939.encode_pgn(j1939.PGN_CCVS1, {"wheel_speed_kmh": 80.0, "brake_switch": 1})
    assert int.from_bytes(data[1:3], "little") == 80 * 256
    assert (data[3] >> 4) & 0x3 == 1


def test_ids_round_trip():
    ident = j1939.make_id(j1939.PGN_CCVS1, 0x00, priority=6)
    assert ident == 0x18FEF100
    assert j1939.parse_id(ident) == (6, j1939.PGN_CCVS1, 0x00, 0xFF)
    req = j1939.make_id(j1939.PGN_REQUEST, 0xF9, destination=0x00)
    assert j1939.parse_id(req) == (6, j1939.PGN_REQUEST, 0xF9, 0x00)


def test_ec1_bam_carries_reference_torque():
    data = j1939.encode_pgn(j1939.PGN_EC1, {"engine_reference_torque_nm": 2300.0})
    frames = j1939.bam_frames(j1939.PGN_EC1, data)
    assert frames[0][0] == j1939.TP_CM_BAM and frames[0][3] == 6 and len(frames) == 7
    body = b"".join(f[1:] for f in frames[1:])[:39]
    assert j1939.decode_pgn(j1939.PGN_EC1, body)["engine_reference_torque_nm"] == 2300.0


@pytest.mark.parametrize("pid, value", [(0x0C, 1234.5), (0x0D, 88), (0x62, -20), (0x63, 2300), (0x46, 12)])
def test_obd_round_trip(pid, value):
    frame = obd.response_frame(pid, value)
    assert frame[1] == 0x41 and frame[2] == pid
    assert obd.PIDS[pid].decode(list(frame[3:3 + obd.PIDS[pid].n_bytes])) == pytest.approx(value)
