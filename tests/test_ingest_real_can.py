"""Real J1939 recordings (CANedge MF4, see tests/data/real-can/README.md) through the ingest."""

from pathlib import Path

import cantools
import numpy as np
import pytest

from haulprofile.analysis.cli import main
from haulprofile.analysis.ingest import foreign, ingest_logs, j1939_decode, read_logs
from haulprofile.contract import j1939

RECORDINGS = {"css-j1939-idle-127s.MF4": 57_849, "css-j1939-tp-186s.MF4": 1_815}


@pytest.fixture(scope="module", params=sorted(RECORDINGS))
def recording(request, data_dir):
    path = data_dir / "real-can" / request.param
    frames, _ = foreign.read_can_log(path)
    return request.param, path, frames


def test_mf4_import_keeps_every_frame(recording):
    name, _, frames = recording
    assert len(frames) == RECORDINGS[name]
    assert np.all(np.diff(frames["t_mono_ns"].astype(np.int64)) >= 0)


def _naive_bam(frames):
    """Independent reference: after each BAM announcement take the sender's next TP.DT frames."""
    ids = frames["arbitration_id"]
    out = []
    for k in np.flatnonzero(((ids >> 16) & 0xFF) == 0xEC):
        data = frames["data"][k].tobytes()
        if data[0] != j1939.TP_CM_BAM:
            continue
        size, packets, pgn = data[1] | data[2] << 8, data[3], int.from_bytes(data[5:8], "little")
        source = ids[k] & 0xFF
        dts = [j for j in range(k + 1, len(frames)) if ((ids[j] >> 16) & 0xFF) == 0xEB and (ids[j] & 0xFF) == source]
        parts = [frames["data"][j].tobytes() for j in dts[:packets]]
        if len(parts) == packets and [p[0] for p in parts] == list(range(1, packets + 1)):
            out.append((int(source), pgn, b"".join(p[1:] for p in parts)[:size]))
    return out


def test_bam_reassembly_matches_naive_reference(recording):
    _, _, frames = recording
    messages, stats = j1939_decode.reassemble(j1939_decode.tp_frames(frames))
    assert stats.bam > 10
    ours = [(m.source, m.pgn, m.data) for m in messages]
    assert sorted(ours) == sorted(_naive_bam(frames))


EC1_DBC = """VERSION ""

NS_ :

BS_:

BU_:

BO_ 2566841342 EC1: 40 Vector__XXX
 SG_ EngineReferenceTorque : 152|16@1+ (1,0) [0|64255] "Nm" Vector__XXX
 SG_ EngineSpeedAtPoint5 : 96|16@1+ (0.125,0) [0|8031.875] "rpm" Vector__XXX
"""


def test_ec1_reference_torque_comes_from_bam(recording):
    """EC1 (39+ bytes, only ever sent by BAM) gives the engine reference torque; cantools decodes
    the same reassembled bytes with a DBC written from J1939-71 (SPN 544: bytes 20-21, 1 Nm/bit)."""
    name, path, frames = recording
    messages, _ = j1939_decode.reassemble(j1939_decode.tp_frames(frames))
    ec1 = [m for m in messages if m.pgn == j1939.PGN_EC1]
    assert ec1, "EC1 must be present in the recording's BAM sessions"
    message = cantools.database.load_string(EC1_DBC, "dbc").get_message_by_name("EC1")
    expected = {message.decode(m.data.ljust(40, b"\xff"))["EngineReferenceTorque"] for m in ec1}
    assert len(expected) == 1
    reference = expected.pop()
    assert 500 <= reference <= 4000  # a heavy-duty diesel
    table = read_logs([path])
    assert set(np.unique(table["engine_reference_torque_nm"].dropna())) == {reference}
    torque_pct = j1939_decode.decode_block(frames)[j1939.PGN_EEC1].values["actual_engine_torque_pct"]
    assert np.nanmax(table["engine_torque_nm"]) <= np.nanmax(torque_pct) / 100 * reference + 1e-9


def test_real_dbc_matches_cantools_on_real_frames(recording, data_dir):
    """The recordings' own J1939 DBC through cantools (PGN match via frame_id_mask) vs our decoding."""
    _, _, frames = recording
    database = cantools.database.load_file(str(data_dir / "real-can" / "CSS-Electronics-SAE-J1939-DEMO.dbc"),
                                           frame_id_mask=0x03FFFF00)
    decoded = j1939_decode.decode_block(frames)
    pairs = {"EEC1": (j1939.PGN_EEC1, "EngineSpeed", "engine_speed_rpm"),
             "CCVS1": (j1939.PGN_CCVS1, "WheelBasedVehicleSpeed", "wheel_speed_kmh")}
    compared = 0
    for message_name, (pgn, dbc_signal, spn_name) in pairs.items():
        ours = decoded[pgn]
        chosen = frames[np.isin(frames["t_mono_ns"].astype(np.int64), ours.time_ns)
                        & (j1939_decode.pgn_and_source(frames["arbitration_id"])[0] == pgn)]
        assert len(chosen) == len(ours.time_ns)
        for k, frame in enumerate(chosen):
            message = database.get_message_by_frame_id(int(frame["arbitration_id"]))
            assert message.name == message_name
            value = message.decode(frame["data"].tobytes())[dbc_signal]
            if np.isnan(ours.values[spn_name][k]):
                spn = j1939.SPNS[spn_name]
                assert value > spn.max_valid_raw * spn.resolution + spn.offset
            else:
                assert ours.values[spn_name][k] == pytest.approx(value)
            compared += 1
    assert compared > 100


def test_user_dbc_columns_from_real_log(data_dir):
    """A user's DBC adds columns by signal name, multi-packet messages included (tp_j1939.dbc)."""
    path = data_dir / "real-can" / "css-j1939-tp-186s.MF4"
    table = read_logs([path], dbc=data_dir / "real-can" / "tp_j1939.dbc")
    frames, _ = foreign.read_can_log(path)
    messages, _ = j1939_decode.reassemble(j1939_decode.tp_frames(frames))
    message = cantools.database.load_file(str(data_dir / "real-can" / "tp_j1939.dbc")).get_message_by_name("EC1")
    expected = {message.decode(m.data.ljust(40, b"\xff"))["EngineSpeedAtPoint5"] for m in messages
                if m.pgn == j1939.PGN_EC1}
    assert set(np.unique(table["EngineSpeedAtPoint5"].dropna())) <= expected | {np.mean(list(expected))}
    assert table["EngineSpeedAtPoint5"].notna().sum() > 10


def test_idle_recording_signals(data_dir):
    table = read_logs([data_dir / "real-can" / "css-j1939-idle-127s.MF4"])
    assert table.attrs["ingest"]["valid_fraction"] == 1.0
    assert (table["speed_mps"] == 0).all()
    assert table["engine_speed_rpm"].between(640, 660).all()
    assert table["time_s"].iloc[0] == 0 and np.allclose(np.diff(table["time_s"]), 0.1)
    assert table["wall_time_ns"].iloc[0] // 10**9 > 1_600_000_000  # 2021, from the MF4 start time


@pytest.mark.parametrize("name", ["css-j1939-tp-186s.MF4", "css-j1939-idle-127s.MF4"])
@pytest.mark.parametrize("share", [0.3, 0.5, 0.77])
def test_a_cut_canedge_file_is_said_to_be_cut(data_dir, tmp_path, name, share):
    data = (data_dir / "real-can" / name).read_bytes()
    cut = tmp_path / name
    cut.write_bytes(data[:int(len(data) * share)])
    said = []
    table, summary = ingest_logs([cut], say=said.append)
    assert table["time_s"].iloc[-1] < 0.9 * read_logs([data_dir / "real-can" / name])["time_s"].iloc[-1]
    assert len(summary["warnings"]) == 1 and "cut short" in summary["warnings"][0]
    assert said == [f"warning: {summary['warnings'][0]}"]


@pytest.mark.parametrize("name", ["css-j1939-tp-186s.MF4", "css-j1939-idle-127s.MF4"])
def test_whole_canedge_files_are_not_called_cut(data_dir, name):
    _, summary = ingest_logs([data_dir / "real-can" / name])
    assert summary["warnings"] == []


def test_a_cut_finalised_mf4_is_said_to_be_cut(data_dir, tmp_path):
    asammdf = pytest.importorskip("asammdf")
    with asammdf.MDF(str(data_dir / "real-can" / "css-j1939-tp-186s.MF4")) as mdf:
        finalised = Path(mdf.save(str(tmp_path / "finalised.mf4"), overwrite=True))
    assert finalised.read_bytes()[:8] == b"MDF     " and foreign.cut_short(finalised) is None
    cut = tmp_path / "cut.mf4"
    cut.write_bytes(finalised.read_bytes()[:len(finalised.read_bytes()) // 2])
    assert "cut short" in foreign.cut_short(cut)


def test_analyze_info_warns_once_on_a_cut_mf4(data_dir, tmp_path, capsys):
    data = (data_dir / "real-can" / "css-j1939-tp-186s.MF4").read_bytes()
    cut = tmp_path / "cut.MF4"
    cut.write_bytes(data[:len(data) // 2])
    assert main(["info", str(cut)]) == 0
    out, err = capsys.readouterr()
    lines = [line for line in (out + err).splitlines() if "cut short" in line]
    assert len(lines) == 1 and lines[0].startswith("warning: cut.MF4: MF4 file cut short")


def test_eec3_friction_and_parasitic_losses_from_real_engines(data_dir):
    """EEC3 (PGN 65247) of both recordings' engines (SA 0): the idling one sends byte 1 = 130 and
    byte 5 = 125 (5 % nominal friction, 0 % parasitic losses of a 2386 Nm reference); the other
    sends byte 1 = 125 (0 %) and byte 5 = 0xFF, not available, which gives no parasitic column."""
    idle = read_logs([data_dir / "real-can" / "css-j1939-idle-127s.MF4"])
    assert np.allclose(idle["engine_friction_torque_nm"], 0.05 * 2386.0)
    assert np.all(idle["engine_parasitic_torque_nm"] == 0.0)
    assert idle.attrs["ingest"]["sources"]["engine_parasitic_torque_nm"]["key"] == "parasitic_loss_torque_pct@0"
    other = read_logs([data_dir / "real-can" / "css-j1939-tp-186s.MF4"])
    assert "engine_parasitic_torque_nm" not in other.columns
    friction = other["engine_friction_torque_nm"].dropna()
    assert len(friction) > 100 and np.all(friction == 0.0)
    frames, _ = foreign.read_can_log(data_dir / "real-can" / "css-j1939-tp-186s.MF4")
    eec3 = j1939_decode.decode_block(frames)[j1939.PGN_EEC3]
    assert np.all(np.isnan(eec3.values["parasitic_loss_torque_pct"]))
