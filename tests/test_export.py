"""``analyze export``: each format read back by the library that owns it (python-can, asammdf,
mcap + jsonschema) and by our own ingest, whose signals table must equal the original's."""

from __future__ import annotations

import json
from pathlib import Path

import can
import numpy as np
import pandas as pd
import pytest

from haulprofile import contract
from haulprofile.analysis import cli
from haulprofile.analysis.export import FORMATS, export_logs, row_times_ns, source
from haulprofile.analysis.ingest import ingest_logs, read_frames
from haulprofile.testing import logs as synthetic

CAN_COLUMNS = ["speed_mps", "engine_speed_rpm", "engine_torque_nm", "driver_demand_torque_pct",
               "accelerator_pedal_pct", "current_gear", "brake_switch", "fuel_rate_lph", "reported_mass_kg"]
"""Columns decoded from CAN alone (what a CAN-only export carries)."""
RESOLUTION_NS = {"blf": 1_000, "asc": 1_000, "candump": 1_000, "mf4": 0}
"""Time resolution of each format as python-can/asammdf read it back [ns] (µs text; BLF times are
float seconds since 1970 inside python-can, some 0.24 µs apart)."""


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    path = tmp_path_factory.mktemp("log") / "drive.mcap"
    with open(path, "wb") as stream:
        synthetic.write_log(stream, 40.0, seed=3, filler_hz=80.0)
    return path


@pytest.fixture(scope="module")
def original(log):
    table, summary = ingest_logs([log])
    return table, summary


def _by_time(table: pd.DataFrame, summary: dict, shift_ns: int = 0) -> pd.DataFrame:
    """The table indexed by each row's absolute time on the exported clock [ns]."""
    return table.set_index(pd.Index(row_times_ns(table, summary) + shift_ns, name="t_ns"))


def _frames_back(kind: str, path) -> list[can.Message]:
    with can.LogReader(str(path)) as reader:
        return [m for m in reader if kind != "asc" or m.arbitration_id or m.dlc]


@pytest.mark.parametrize("kind", ["blf", "asc", "candump", "mf4"])
def test_bus_log_exports_reimport_to_the_same_signals(tmp_path, log, original, kind):
    exported = export_logs([log], kind, tmp_path)[0]
    content = source.load(log)
    assert exported.frames == len(content.frames) > 0
    table, summary = original
    again, again_summary = ingest_logs([exported.target])
    assert again_summary["can_frames"] == len(content.frames)
    before = _by_time(table, summary, content.wall_offset_ns)
    shift = 0 if kind != "asc" else content.wall_offset_ns + int(content.frames["t_mono_ns"][0] // 10**9 * 10**9)
    after = _by_time(again, again_summary, shift)
    after = after[after["valid"]]
    common = before.index.intersection(after.index)
    assert len(common) >= 0.95 * after.shape[0] > 300
    columns = [c for c in CAN_COLUMNS if c in table.columns]
    assert len(columns) >= 7
    pd.testing.assert_frame_equal(before.loc[common, columns], after.loc[common, columns], check_exact=True)


@pytest.mark.parametrize("kind", ["blf", "asc", "candump"])
def test_python_can_reads_back_the_same_frames(tmp_path, log, kind):
    exported = export_logs([log], kind, tmp_path)[0]
    content = source.load(log)
    frames = content.frames
    back = _frames_back(kind, exported.target)
    assert len(back) == len(frames)
    assert [m.arbitration_id for m in back] == frames["arbitration_id"].tolist()
    assert [bytes(m.data) for m in back] == [bytes(d[:n]) for d, n in zip(frames["data"], frames["dlc"])]
    assert [m.is_extended_id for m in back] == ((frames["flags"] & contract.CAN_FLAG_EXTENDED) != 0).tolist()
    assert [m.is_rx for m in back] == ((frames["flags"] & contract.CAN_FLAG_TX) == 0).tolist()
    times = np.array([m.timestamp for m in back])
    expected = content.times_ns(frames["t_mono_ns"]) / 1e9
    if kind == "asc":  # python-can reads ASC times relative to the measurement start
        expected = expected - np.floor(expected[0])
    assert np.max(np.abs(times - expected)) <= RESOLUTION_NS[kind] / 1e9 * 1.01


def test_asammdf_reads_canedge_bus_logging_channels(tmp_path, log):
    from asammdf import MDF
    from asammdf.blocks import v4_constants as v4c

    exported = export_logs([log], "mf4", tmp_path)[0]
    content = source.load(log)
    frames = content.frames
    with MDF(str(exported.target)) as mdf:
        groups = {g.channel_group.acq_name: (i, g) for i, g in enumerate(mdf.groups)}
        index, group = groups["CAN_DataFrame"]
        assert group.channel_group.flags & v4c.FLAG_CG_BUS_EVENT
        assert group.channel_group.acq_source.bus_type == v4c.BUS_TYPE_CAN
        ids = mdf.get("CAN_DataFrame.ID", group=index)
        start_ns = int(mdf.start_time.timestamp()) * 10**9
        np.testing.assert_array_equal(ids.samples, frames["arbitration_id"])
        np.testing.assert_array_equal(mdf.get("CAN_DataFrame.DataBytes", group=index).samples, frames["data"])
        np.testing.assert_array_equal(mdf.get("CAN_DataFrame.DLC", group=index).samples, frames["dlc"])
        np.testing.assert_array_equal(mdf.get("CAN_DataFrame.IDE", group=index).samples,
                                      (frames["flags"] & contract.CAN_FLAG_EXTENDED) != 0)
        np.testing.assert_array_equal(mdf.get("CAN_DataFrame.Dir", group=index).samples,
                                      (frames["flags"] & contract.CAN_FLAG_TX) != 0)
        np.testing.assert_array_equal(np.round(ids.timestamps * 1e9).astype(np.int64) + start_ns,
                                      content.times_ns(frames["t_mono_ns"]))
        speed = mdf.get("speed_mps")
        assert speed.unit == "m/s"
        assert mdf.get("engine_speed_rpm").unit == "rpm"
        table, summary = ingest_logs([log])
        np.testing.assert_array_equal(speed.samples, table["speed_mps"].to_numpy())
        np.testing.assert_allclose(speed.timestamps * 1e9 + start_ns,
                                   row_times_ns(table, summary) + content.wall_offset_ns, atol=1)


def test_asammdf_decodes_the_export_with_a_dbc(tmp_path, data_dir):
    """asammdf's own bus-logging decoder finds the frames of an exported CANedge recording."""
    from asammdf import MDF

    dbc = data_dir / "real-can" / "CSS-Electronics-SAE-J1939-DEMO.dbc"
    original = data_dir / "real-can" / "css-j1939-idle-127s.MF4"
    exported = export_logs([original], "mf4", tmp_path)[0]
    decoded = {}
    for path in (original, exported.target):
        with MDF(str(path)) as mdf:
            with mdf.extract_bus_logging({"CAN": [(str(dbc), 0)]}) as out:
                decoded[path] = {name: out.get(name).samples for name in ("EngineSpeed",)
                                 if name in out.channels_db}
    assert decoded[original].keys() == decoded[exported.target].keys() == {"EngineSpeed"}
    np.testing.assert_array_equal(decoded[original]["EngineSpeed"], decoded[exported.target]["EngineSpeed"])


def test_foxglove_copy_decodes_with_mcap_and_json_schema_alone(tmp_path, log):
    import jsonschema
    from mcap.reader import make_reader

    exported = export_logs([log], "foxglove", tmp_path)[0]
    table, summary = ingest_logs([log])
    arrays = read_frames([log])
    seen: dict[str, list] = {}
    with open(exported.target, "rb") as stream:
        reader = make_reader(stream)
        for schema, channel, message in reader.iter_messages(log_time_order=True):
            assert schema.encoding == "jsonschema" and channel.message_encoding == "json"
            record = json.loads(message.data)
            seen.setdefault(channel.topic, []).append((schema, message, record))
    assert {"/signals", "/imu", "/gps/fix", "/can/frames", "/barometer"} <= set(seen)
    for topic, entries in seen.items():
        validator = jsonschema.Draft202012Validator(json.loads(entries[0][0].data))
        step = max(1, len(entries) // 500)
        for _, _, record in entries[::step]:
            validator.validate(record)
    signals = [r for _, _, r in seen["/signals"]]
    assert len(signals) == len(table)
    np.testing.assert_array_equal(np.array([r["speed_mps"] for r in signals], float), table["speed_mps"].to_numpy())
    schema = json.loads(seen["/signals"][0][0].data)
    assert schema["properties"]["engine_speed_rpm"]["unit"] == "rpm"
    scale = float(arrays.channel_metadata["/imu"]["accel_scale_mps2_per_lsb"])
    imu = [r for _, _, r in seen["/imu"]]
    assert len(imu) == len(arrays.imu)
    np.testing.assert_allclose([r["linear_acceleration"]["z"] for r in imu], arrays.imu["accel_raw"][:, 2] * scale)
    assert 9.0 < np.median([r["linear_acceleration"]["z"] for r in imu]) < 10.6
    fixes = [r for _, _, r in seen["/gps/fix"]]
    assert seen["/gps/fix"][0][0].name == "foxglove.LocationFix"
    assert all(-90 <= f["latitude"] <= 90 and -180 <= f["longitude"] <= 180 for f in fixes)
    assert len(seen["/can/frames"]) == len(arrays.can)


def test_private_export_has_no_time_of_day_positions_or_position_frames(tmp_path, log):
    from mcap.reader import make_reader

    frames = source.load(log).frames
    position = frames[:50].copy()
    position["arbitration_id"] = (6 << 26) | (65267 << 8) | 0x17  # J1939 Vehicle Position from SA 0x17
    candump = tmp_path / "in" / "drive.log"
    candump.parent.mkdir()
    with can.CanutilsLogWriter(str(candump)) as writer:
        for f in np.concatenate([frames[:200], position]):
            writer.on_message_received(can.Message(timestamp=int(f["t_mono_ns"]) / 1e9 + 1.7e9,
                                                   arbitration_id=int(f["arbitration_id"]), dlc=8,
                                                   data=f["data"].tobytes(), channel="can0"))
    out = tmp_path / "out"
    exported = export_logs([candump], "candump", out, private=True)[0]
    back = _frames_back("candump", exported.target)
    assert len(back) == 200
    assert max(m.timestamp for m in back) < 946_684_800  # no wall clock: before 2000-01-01
    fox = export_logs([log], "foxglove", out, private=True)[0]
    with open(fox.target, "rb") as stream:
        summary = make_reader(stream).get_summary()
    topics = {c.topic for c in summary.channels.values()}
    assert not topics & {"/gps/fix", "/gps/nmea", "/time/sync"}
    assert summary.statistics.message_start_time < 946_684_800 * 10**9
    with open(fox.target, "rb") as stream:
        record = next(json.loads(m.data) for _, c, m in make_reader(stream).iter_messages(topics=["/signals"]))
    assert "latitude_deg" not in record and "longitude_deg" not in record


def test_export_never_writes_over_a_file(tmp_path, log, capsys):
    out = tmp_path / "out"
    assert cli.main(["export", str(log), "--to", "candump", "-o", str(out)]) == 0
    capsys.readouterr()
    target = out / "drive.log"
    before = target.read_bytes()
    assert cli.main(["export", str(log), "--to", "candump", "-o", str(out)]) == 2
    error = capsys.readouterr().err.strip().splitlines()
    assert len(error) == 1 and "exists" in error[0] and "Traceback" not in error[0]
    assert target.read_bytes() == before
    # exporting a candump log as candump into its own directory would be the input itself
    assert cli.main(["export", str(target), "--to", "candump", "-o", str(out)]) == 2
    assert target.read_bytes() == before
    assert sorted(p.name for p in out.iterdir()) == ["drive.log"]


def test_unknown_or_missing_input_is_one_line(tmp_path, capsys):
    assert cli.main(["export", str(tmp_path / "nothing.mcap"), "--to", "mf4", "-o", str(tmp_path)]) == 2
    assert "not found" in capsys.readouterr().err
    table = tmp_path / "signals.csv"
    pd.DataFrame({"time_s": [0.0, 0.1], "speed_mps": [1.0, 1.0]}).to_csv(table, index=False)
    assert cli.main(["export", str(table), "--to", "blf", "-o", str(tmp_path / "out")]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "no CAN frames to export" in error
    assert not (tmp_path / "out").exists()


def _flag_frames() -> source.LogContent:
    """Data frames (standard and extended id), a remote frame, a frame the logger sent, an error frame."""
    from haulprofile.contract import CAN_FLAG_ERROR, CAN_FLAG_EXTENDED, CAN_FLAG_REMOTE, CAN_FLAG_TX, CAN_FRAME_DTYPE

    frames = np.zeros(5, CAN_FRAME_DTYPE)
    frames["t_mono_ns"] = 7_000_000_000 + np.arange(5) * 1_000_000
    frames["arbitration_id"] = [0x123, 0x18FEF100, 0x7DF, 0x18EAFFF9, 0]
    frames["flags"] = [0, CAN_FLAG_EXTENDED, CAN_FLAG_REMOTE, CAN_FLAG_EXTENDED | CAN_FLAG_TX, CAN_FLAG_ERROR]
    frames["dlc"] = [2, 8, 8, 3, 0]
    frames["channel"] = [0, 1, 0, 1, 0]
    frames["data"][0, :2] = [1, 2]
    frames["data"][1] = np.arange(8) + 10
    frames["data"][3, :3] = [0xEC, 0xFE, 0x00]
    return source.LogContent(Path("flags.log"), frames, 1_700_000_000 * 10**9)


@pytest.mark.parametrize("kind", ["blf", "asc", "candump"])
def test_flags_and_buses_survive_python_can(tmp_path, kind):
    from haulprofile.analysis.export import bus_logs

    content = _flag_frames()
    target = tmp_path / f"flags{FORMATS[kind]}"
    bus_logs.write(content, target, kind)
    with can.LogReader(str(target)) as reader:
        back = [m for m in reader if m.is_error_frame or m.arbitration_id or m.dlc]
    assert [m.is_error_frame for m in back] == [False, False, False, False, True]
    assert [m.is_remote_frame for m in back[:4]] == [False, False, True, False]
    assert [m.is_extended_id for m in back[:4]] == [False, True, False, True]
    assert [m.is_rx for m in back[:4]] == [True, True, True, False]
    assert [m.arbitration_id for m in back[:4]] == [0x123, 0x18FEF100, 0x7DF, 0x18EAFFF9]
    assert [bytes(m.data) for m in back[:4] if not m.is_remote_frame] == [b"\x01\x02", bytes(range(10, 18)),
                                                                          b"\xec\xfe\x00"]
    buses = [m.channel for m in back[:4]]
    assert buses == (["can0", "can1", "can0", "can1"] if kind == "candump" else [0, 1, 0, 1])


def test_mf4_keeps_remote_frames_apart(tmp_path):
    from asammdf import MDF

    from haulprofile.analysis.export import mf4

    mf4.write(_flag_frames(), tmp_path / "flags.mf4")
    with MDF(str(tmp_path / "flags.mf4")) as mdf:
        groups = {g.channel_group.acq_name: i for i, g in enumerate(mdf.groups)}
        assert set(groups) == {"CAN_DataFrame", "CAN_RemoteFrame"}  # the error frame is left out
        data = groups["CAN_DataFrame"]
        np.testing.assert_array_equal(mdf.get("CAN_DataFrame.ID", group=data).samples,
                                      [0x123, 0x18FEF100, 0x18EAFFF9])
        np.testing.assert_array_equal(mdf.get("CAN_DataFrame.BusChannel", group=data).samples, [0, 1, 1])
        np.testing.assert_array_equal(mdf.get("CAN_DataFrame.Dir", group=data).samples, [0, 0, 1])
        remote = groups["CAN_RemoteFrame"]
        assert mdf.get("CAN_RemoteFrame.ID", group=remote).samples.tolist() == [0x7DF]
        assert mdf.get("CAN_RemoteFrame.DLC", group=remote).samples.tolist() == [8]
        assert mdf.start_time.timestamp() == 1_700_000_007.0
