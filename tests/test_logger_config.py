"""The daemon's TOML configuration: the shipped example, defaults, and one-line errors naming the key."""

from __future__ import annotations

import dataclasses

import pytest

from haulprofile.logger import config as cfg
from haulprofile.logger.sources.can import allowed_tx_ids, transmit_warning


def test_example_is_valid_and_matches_the_defaults():
    example = cfg.load(cfg.example_path())
    assert dataclasses.asdict(example) == dataclasses.asdict(cfg.Config())
    assert example.can.obd.pids == [0x0D, 0x0C, 0x62, 0x63, 0x61, 0x33, 0x46]
    assert example.i2c.lsm9ds1.odr_hz == 952.0


@pytest.mark.parametrize("data, key", [
    ({"can": {"bitrate": "fast"}}, "can.bitrate"),
    ({"can": {"obd": {"rate": 30}}}, "can.obd.rate"),
    ({"gps": {"port": 3}}, "gps.port"),
    ({"logger": {"queue_size": 0}}, "logger.queue_size"),
    ({"can": {"obd": {"pids": [0x0D, 0x99]}}}, "can.obd.pids"),
    ({"can": {"obd": {"addressing": "12bit"}}}, "can.obd.addressing"),
    ({"can": {"j1939": {"source_address": 300}}}, "can.j1939.source_address"),
    ({"i2c": {"lsm9ds1": {"odr_hz": 1000}}}, "i2c.lsm9ds1.odr_hz"),
    ({"i2c": {"lsm9ds1": True}}, "i2c.lsm9ds1"),
    ({"wifi": {}}, "wifi"),
    ({"can": {"listen_only": "yes"}}, "can.listen_only"),
    ({"logger": {"time_scale": 10.0}}, "logger.time_scale"),
    ({"can": {"receive_interval_s": 0.2}}, "can.receive_interval_s"),
])
def test_bad_values_name_the_key(data, key):
    with pytest.raises(cfg.ConfigError) as error:
        cfg.from_dict(data)
    message = str(error.value)
    assert key in message and "\n" not in message


def test_unreadable_and_invalid_files(tmp_path):
    with pytest.raises(cfg.ConfigError, match="cannot read"):
        cfg.load(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[can\n")
    with pytest.raises(cfg.ConfigError, match="not valid TOML"):
        cfg.load(bad)


def test_listen_only_empties_the_allow_list():
    config = cfg.from_dict({"can": {"listen_only": True}})
    assert allowed_tx_ids(config.can) == frozenset()


def test_the_wiring_guide_shows_configuration_the_logger_accepts():
    """docs/raspberry-pi.md: its TOML snippets load, the Sense HAT's LSM9DS1 addresses among them, and
    every MCP2515 overlay line names the crystal and the interrupt pin."""
    import re
    import tomllib
    from pathlib import Path

    guide = (Path(__file__).resolve().parents[1] / "docs" / "raspberry-pi.md").read_text()
    snippets = [block for block in re.findall(r"```\n(.*?)```", guide, re.S) if block.lstrip().startswith("[i2c")]
    assert snippets, "the Sense HAT's addresses are shown as a configuration snippet"
    for snippet in snippets:
        config = cfg.from_dict(tomllib.loads(snippet))
        assert (config.i2c.lsm9ds1.address_ag, config.i2c.lsm9ds1.address_m) == (0x6A, 0x1C)
    overlays = re.findall(r"dtoverlay=mcp2515-can0[^\s']*", guide)
    assert len(overlays) >= 2
    assert all(re.search(r"oscillator=\d{7,8}\b", o) and re.search(r"interrupt=\d+\b", o) for o in overlays)
    assert allowed_tx_ids(cfg.from_dict({"can": {"listen_only": False}}).can)


def test_listen_only_is_the_default_everywhere():
    """Defaults, the shipped example and a config without the key transmit nothing; transmitting
    is said in one line at start."""
    assert cfg.Config().can.listen_only is True
    assert cfg.load(cfg.example_path()).can.listen_only is True
    assert cfg.from_dict({"can": {"obd": {"enabled": True}}}).can.listen_only is True
    assert transmit_warning(cfg.Config().can) is None
    line = transmit_warning(cfg.from_dict({"can": {"listen_only": False}}).can)
    assert line.startswith("TRANSMITTING on can0") and "OBD-II requests at 30 Hz" in line
    assert "PGN 65251, 65258" in line and "\n" not in line


def test_more_can_channels_are_distinct_buses():
    assert cfg.from_dict({"can": {"channel": "can0", "more_channels": ["can1"]}}).can.more_channels == ["can1"]
    for bad in (["can0"], ["can1", "can1"], "can1"):
        with pytest.raises(cfg.ConfigError, match="more_channels"):
            cfg.from_dict({"can": {"channel": "can0", "more_channels": bad}})
