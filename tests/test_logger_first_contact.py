"""The logger as a new user meets it: one line for every bad config or log directory, ``--check``
tries what start needs, ``--status`` is unhealthy when the enabled devices did not open."""

from __future__ import annotations

import pytest

from haulprofile import contract
from haulprofile.logger import cli
from haulprofile.logger import config as cfg
from haulprofile.logger.storage import LogDirectory, StorageOptions


def run(capsys, *argv):
    code = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def one_line(code, err, *words):
    assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    for word in words:
        assert word in err, err


def test_a_utf16_config_is_one_line(tmp_path, capsys):
    path = tmp_path / "logger.toml"
    path.write_bytes('[logger]\ndirectory = "logs"\n'.encode("utf-16"))
    one_line(*run(capsys, "--config", path, "--check")[::2], "UTF-16")


def test_invalid_bytes_and_an_empty_config_are_one_line(tmp_path, capsys):
    path = tmp_path / "logger.toml"
    path.write_bytes(b'[logger]\ndirectory = "\xff\xfe"\n')
    one_line(*run(capsys, "--config", path, "--check")[::2], "UTF-8")
    path.write_text("\n# nothing set\n")
    one_line(*run(capsys, "--config", path, "--check")[::2], "sets nothing")


@pytest.mark.parametrize("data, key", [
    ({"i2c": {"lps25hb": {"address": 0x1FF}}}, "i2c.lps25hb.address"),
    ({"i2c": {"lsm9ds1": {"address_m": 0x03}}}, "i2c.lsm9ds1.address_m"),
    ({"storage": {"min_free_mb": -1}}, "storage.min_free_mb"),
])
def test_impossible_values_name_the_key(data, key):
    with pytest.raises(cfg.ConfigError, match=key.replace(".", r"\.")):
        cfg.from_dict(data)


def test_check_tries_the_log_directory_as_start_does(tmp_path, capsys):
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    path = tmp_path / "logger.toml"
    path.write_text(f'[logger]\ndirectory = "{blocker / "logs"}"\n')
    one_line(*run(capsys, "--config", path, "--check")[::2], "logger.directory")
    one_line(*run(capsys, "--config", path, "--duration", "1")[::2], "logger.directory")
    path.write_text(f'[logger]\ndirectory = "{tmp_path / "logs"}"\n')
    code, out, _ = run(capsys, "--config", path, "--check")
    assert code == 0 and "writable" in out and not list((tmp_path / "logs").iterdir())


def test_status_is_unhealthy_when_no_enabled_source_opened(tmp_path, capsys):
    directory = LogDirectory(StorageOptions(tmp_path / "logs", min_free_bytes=0))
    directory.open()
    record = {"t_mono_ns": 1, "sources": {}, "queue_depth": 0, "disk_free_bytes": 10**10,
              "messages": ["can: cannot open socketcan can0", "gps: cannot open /dev/ttyACM0"],
              "paused_drops": 0, "file": directory.path.name}
    directory.writer.write(contract.DIAGNOSTICS, contract.encode_json(record), 1, 1)
    directory.close()
    path = tmp_path / "logger.toml"
    path.write_text(f'[logger]\ndirectory = "{tmp_path / "logs"}"\n')
    code, out, _ = run(capsys, "--config", path, "--status")
    assert code == 1 and "not open" in out and "can" in out and "gps" in out


def test_version(capsys):
    with pytest.raises(SystemExit) as exit_info:
        cli.main(["--version"])
    assert exit_info.value.code == 0 and capsys.readouterr().out.startswith("haulprofile-logger (haulprofile) ")
