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
