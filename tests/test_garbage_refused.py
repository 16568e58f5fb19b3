"""Values that were taken silently or hung without a word: each is now one line naming the key or
the address, and a non-zero exit."""

from __future__ import annotations

import socket
import threading

import pytest

from haulprofile.logger import config as cfg


def config_with(tmp_path, text: str):
    path = tmp_path / "logger.toml"
    path.write_text(f'[logger]\ndirectory = "{tmp_path / "logs"}"\n' + text)
    return path


@pytest.mark.parametrize("prefix", ["a/b", "../escape", ".hidden", "", "x" * 100])
def test_a_log_prefix_that_is_not_a_plain_name_is_refused(tmp_path, prefix):
    path = tmp_path / "logger.toml"
    path.write_text(f'[logger]\ndirectory = "{tmp_path / "logs"}"\nprefix = "{prefix}"\n')
    with pytest.raises(cfg.ConfigError, match="logger.prefix"):
        cfg.load(path)
    assert not (tmp_path / "escape").exists()


@pytest.mark.parametrize("key, value", [("storage", "rotate_interval_s = inf"), ("storage", "min_free_mb = nan"),
                                        ("storage", "chunk_interval_s = inf")])
def test_infinite_or_nan_settings_are_refused(tmp_path, key, value):
    path = tmp_path / "logger.toml"
    path.write_text(f'[logger]\ndirectory = "{tmp_path / "logs"}"\n[{key}]\n{value}\n')
    with pytest.raises(cfg.ConfigError, match="finite"):
        cfg.load(path)


def test_a_port_that_is_not_a_dask_scheduler_is_one_error_not_a_silent_wait(monkeypatch):
    pytest.importorskip("distributed")
    from haulprofile.analysis.fleet import runner

    silent = socket.socket()
    silent.bind(("127.0.0.1", 0))
    silent.listen(8)
    accepted = []
    threading.Thread(target=lambda: [accepted.append(silent.accept()) for _ in range(8)], daemon=True).start()
    monkeypatch.setattr(runner, "DASK_CONNECT_WAIT_S", 2.0)
    try:
        with pytest.raises(runner.FleetError, match="no Dask scheduler answered"):
            runner.executor_for(scheduler=f"tcp://127.0.0.1:{silent.getsockname()[1]}")
    finally:
        silent.close()
    assert accepted, "the connection was made: the port answered TCP, not as a scheduler"


def drive_csv(tmp_path, **columns):
    import numpy as np
    import pandas as pd

    from haulprofile.testing.drives import synthetic_drive

    frame = synthetic_drive(300, seed=4).round(3).drop(columns=["distance_m"])
    n = len(frame)
    for name, value in columns.items():
        frame[name] = value(n) if callable(value) else np.full(n, value)
    path = tmp_path / "drive.csv"
    frame.to_csv(path, index=False)
    return path


@pytest.mark.parametrize("column, value, unit", [("pressure_pa", 1013.0, "hPa"), ("pressure_pa", 101.3, "kPa"),
                                                 ("air_temperature_c", 293.0, "kelvin")])
def test_a_column_in_another_unit_is_refused_naming_it(tmp_path, column, value, unit):
    from haulprofile.analysis.errors import UserError
    from haulprofile.analysis.signals import combine

    with pytest.raises(UserError, match=unit):
        combine([drive_csv(tmp_path, **{column: value})])


@pytest.mark.parametrize("column, bad", [("pressure_pa", 1e308), ("pressure_pa", -5.0), ("latitude_deg", 200.0),
                                         ("engine_torque_nm", 1e12)])
def test_implausible_samples_are_left_out_with_a_note(tmp_path, column, bad):
    import numpy as np

    from haulprofile.analysis.signals import combine

    typical = {"pressure_pa": 95_000.0, "latitude_deg": 48.1, "engine_torque_nm": 800.0}[column]

    def with_spikes(n):
        values = np.full(n, typical)
        values[::50] = bad
        return values

    said = []
    frame = combine([drive_csv(tmp_path, **{column: with_spikes})], said.append)
    values = frame[column].to_numpy()
    assert np.isnan(values[::50]).all() and np.isfinite(np.delete(values, np.s_[::50])).all()
    assert any(column in line and "left out" in line for line in said), said


@pytest.mark.parametrize("out", ["/proc/haulprofile-out", b"o\xff".decode("utf-8", "surrogateescape")])
def test_outputs_that_cannot_be_written_are_one_line_before_any_stage(tmp_path, capsys, out):
    from haulprofile.analysis.cli import main

    code = main(["run", str(drive_csv(tmp_path)), "--vehicle", "rigid-18t", "--out", out])
    captured = capsys.readouterr()
    err = captured.err
    assert code == 2 and "internal error" not in err and err.strip().count("\n") == 0, err
    assert "[kinematics]" not in captured.out, "refused before any stage ran"


@pytest.mark.parametrize("inputs", [None, b"logs/", [None], 3, []])
def test_the_python_api_given_no_paths_says_so(inputs):
    from haulprofile import analysis
    from haulprofile.analysis.errors import UserError

    with pytest.raises(UserError, match="inputs must be a path"):
        analysis.run(inputs, vehicle="rigid-18t")


@pytest.mark.parametrize("item", ["1=0.001", "2=1e9", "inf", "1=nan"])
def test_a_known_mass_no_road_vehicle_has_is_refused(item):
    from haulprofile.analysis.errors import UserError
    from haulprofile.analysis.commands.arguments import parse_fleet_known_masses
    from haulprofile.analysis.commands.arguments import parse_known_masses

    with pytest.raises(UserError, match="--known-mass"):
        parse_known_masses([item])
    with pytest.raises(UserError, match="--known-mass"):
        parse_fleet_known_masses([f"rigid:drive.mcap:{item if '=' in item else '1=' + item}"])


def test_a_can_fd_frame_is_flagged_and_counted_not_stored_as_a_classic_one():
    import asyncio

    import can

    from haulprofile import contract
    from haulprofile.logger.clock import Clock
    from haulprofile.logger.config import CanSection
    from haulprofile.logger.sources.can import CanSource

    channel = "fd-frames"
    player = can.Bus(interface="virtual", channel=channel)
    logger_bus = can.Bus(interface="virtual", channel=channel)

    async def main():
        queue = asyncio.Queue(1000)
        source = CanSource(queue, Clock(), CanSection(interface="virtual"), logger_bus)
        task = asyncio.create_task(source.run())
        player.send(can.Message(arbitration_id=0x18FF0017, data=bytes(range(64)), is_extended_id=True, is_fd=True))
        player.send(can.Message(arbitration_id=0x0CF00400, data=bytes(range(8)), is_extended_id=True))
        await asyncio.sleep(0.3)
        source.update_extra()
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
        await source.close()
        return source, b"".join(queue.get_nowait().payload for _ in range(queue.qsize()))

    source, payload = asyncio.run(main())
    player.shutdown()
    frames = contract.unpack(contract.CAN_FRAMES, payload)
    fd = frames[frames["arbitration_id"] == 0x18FF0017]
    classic = frames[frames["arbitration_id"] == 0x0CF00400]
    assert len(fd) == 1 and fd["flags"][0] & contract.CAN_FLAG_FD and fd["dlc"][0] == 64
    assert not classic["flags"][0] & contract.CAN_FLAG_FD
    assert source.stats.extra["fd_truncated"] == 1


class StuckBus:
    """An SMBus whose data registers all read ``value`` (a held SDA line reads 0x00 or 0xFF);
    the barometer's FIFO always holds 4 samples."""

    def __init__(self, value: int):
        self.value = value

    def read_byte_data(self, address, register):
        return 4 if register == 0x2F else self.value

    def write_byte_data(self, address, register, value):
        pass

    def read_i2c_block_data(self, address, register, length):
        return [self.value] * length


@pytest.mark.parametrize("value", [0x00, 0xFF])
def test_a_stuck_i2c_sensor_is_said_and_its_state_is_not_running(value):
    import asyncio

    from haulprofile.logger.clock import Clock
    from haulprofile.logger.sources.i2c.base import RAIL_LIMIT, I2cBusSource
    from haulprofile.logger.sources.i2c.lps25hb import Lps25hb

    said = []
    driver = Lps25hb(StuckBus(value), 0x5C, Clock())
    source = I2cBusSource(asyncio.Queue(10_000), Clock(), [driver], say=said.append)
    for _ in range(RAIL_LIMIT // 4 + 2):
        source._emit_all(source._poll_round({driver.name: 0}, 1))
    assert source.stats.extra["lps25hb"]["state"] == "stuck"
    assert any("0x00 or 0xFF" in line for line in said), said


def test_an_imu_at_full_scale_is_said_saturated():
    import asyncio

    from haulprofile.logger.clock import Clock
    from haulprofile.logger.sources.i2c.base import RAIL_LIMIT, I2cBusSource
    from haulprofile.logger.sources.i2c.lsm9ds1 import Lsm9ds1

    class Saturated(StuckBus):
        def read_byte_data(self, address, register):
            return 8  # FIFO_SRC: 8 samples waiting

        def read_i2c_block_data(self, address, register, length):
            return [0x10, 0x02, 0x33, 0x01, 0xFF, 0x7F][:length]  # z at +32767: beyond the range

    said = []
    driver = Lsm9ds1(Saturated(0), 0x6A, Clock())
    source = I2cBusSource(asyncio.Queue(10_000), Clock(), [driver], say=said.append)
    for _ in range(RAIL_LIMIT // 8 + 2):
        source._emit_all(source._poll_round({driver.name: 0}, 1))
    assert source.stats.extra[driver.name]["state"] == "saturated"
    assert any("full scale" in line for line in said), said


def synthetic_log(tmp_path, name="log.mcap"):
    from haulprofile.testing import logs as synthetic

    path = tmp_path / name
    with open(path, "wb") as stream:
        synthetic.write_log(stream, 20, seed=2)
    return path


def test_a_dbc_signal_named_like_one_of_our_columns_does_not_replace_it(tmp_path, data_dir):
    import numpy as np

    from haulprofile.analysis.ingest import ingest_logs

    log = synthetic_log(tmp_path)
    plain, _ = ingest_logs([log])
    dbc = tmp_path / "clash.dbc"
    text = (data_dir / "real-can" / "CSS-Electronics-SAE-J1939-DEMO.dbc").read_text()
    dbc.write_text(text.replace("EngineSpeed", "speed_mps"))
    table, _ = ingest_logs([log], dbc=dbc)
    assert np.allclose(table["speed_mps"], plain["speed_mps"], equal_nan=True)
    assert "dbc_speed_mps" in table and np.nanmax(table["dbc_speed_mps"]) > 100  # the engine's rpm, kept apart


@pytest.mark.parametrize("scale", [float("nan"), float("inf"), 0.0, -0.0006])
def test_an_imu_scale_that_is_no_number_leaves_the_accelerations_out_with_a_warning(tmp_path, monkeypatch, scale):
    from haulprofile.analysis.ingest import ingest_logs
    from haulprofile.testing import logs as synthetic

    monkeypatch.setattr(synthetic, "ACCEL_SCALE_MPS2_PER_LSB", scale)
    said = []
    table, _ = ingest_logs([synthetic_log(tmp_path)], say=said.append)
    assert "accel_x_mps2" not in table or table["accel_x_mps2"].isna().all()
    assert any("accel_scale_mps2_per_lsb" in line for line in said), said


@pytest.mark.parametrize("text", ["speed_rpm,torque_nm,efficiency\n1000,100,high\n1000,200,0.9\n",
                                  "speed_rpm,torque_nm,efficiency\n1000,100,0.9\nfast,200,0.9\n",
                                  "speed_rpm,torque_nm,efficiency\n1000,inf,0.9\n2000,100,0.9\n"])
def test_a_non_numeric_efficiency_map_is_one_line(tmp_path, text):
    from haulprofile.analysis.errors import UserError
    from haulprofile.analysis.simulate.model import efficiency_map

    path = tmp_path / "map.csv"
    path.write_text(text)
    with pytest.raises(UserError, match="finite number"):
        efficiency_map(path)


@pytest.mark.parametrize("content", ["privacy = 5\n".encode(), "zones = \"home\"\n".encode(),
                                     '[[zones]]\nname = "d"\nlat = 48.0\nlon = 11.0\nradius_m = 100\n'.encode("utf-16")])
def test_zone_files_of_the_wrong_shape_or_encoding_are_one_line(tmp_path, content):
    from haulprofile.analysis.errors import UserError
    from haulprofile.analysis.redact import load_zones

    path = tmp_path / "zones.toml"
    path.write_bytes(content)
    with pytest.raises(UserError, match="--zones"):
        load_zones(path)


@pytest.mark.parametrize("address", ["tls://127.0.0.1:1", "ucx://127.0.0.1:1"])
def test_schedulers_of_other_protocols_are_one_error(address):
    pytest.importorskip("distributed")
    from haulprofile.analysis.fleet import runner

    with pytest.raises(runner.FleetError, match="Dask scheduler"):
        runner.executor_for(scheduler=address)


def test_a_dbc_signal_longer_than_its_message_is_refused(tmp_path, data_dir):
    from haulprofile.analysis.errors import UserError
    from haulprofile.analysis.ingest import ingest_logs

    dbc = tmp_path / "wide.dbc"
    text = (data_dir / "real-can" / "CSS-Electronics-SAE-J1939-DEMO.dbc").read_text()
    dbc.write_text(text.replace("SG_ EngineSpeed : 24|16@1+", "SG_ EngineSpeed : 0|128@1+"))
    with pytest.raises(UserError, match="EngineSpeed is 128 bits"):
        ingest_logs([synthetic_log(tmp_path)], dbc=dbc)


def test_a_battery_that_cannot_deliver_the_machines_power_is_refused(tmp_path):
    from haulprofile.analysis.errors import UserError
    from haulprofile.analysis.vehicle import load_vehicle
    from importlib import resources

    text = resources.files("haulprofile.analysis.data.vehicles").joinpath("rigid-18t.toml").read_text()
    text = text.replace("battery_voltage_v = 650.0", "battery_voltage_v = 12.0").replace(
        "battery_internal_resistance_ohm = 0.045", "battery_internal_resistance_ohm = 5.0")
    assert "battery_voltage_v = 12.0" in text and "= 5.0" in text
    path = tmp_path / "toy.toml"
    path.write_text(text)
    with pytest.raises(UserError, match="U²/4R"):
        load_vehicle(path)
