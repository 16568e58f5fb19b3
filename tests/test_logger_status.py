"""``haulprofile-logger --status``: the newest log's last `/diagnostics`, read while written."""

from __future__ import annotations

from mcap.reader import make_reader

from haulprofile import contract
from haulprofile.logger import cli
from haulprofile.logger.config import Config
from haulprofile.logger.emulators.rig import record_drive
from haulprofile.logger.emulators.signals import synthetic_drive
from haulprofile.logger.status import last_diagnostics


def _just_after_the_first_diagnostics(path) -> int:
    """A cut a few bytes into the record after the first chunk that holds `/diagnostics` (which
    chunk that is depends on when the daemon's first second ended: half the file was a race)."""
    with open(path, "rb") as stream:
        summary = make_reader(stream).get_summary()
    channel = next(c.id for c in summary.channels.values() if c.topic == contract.DIAGNOSTICS.name)
    first = next(c for c in summary.chunk_indexes if channel in c.message_index_offsets)
    return first.chunk_start_offset + first.chunk_length + first.message_index_length + 10


def test_status_of_a_log_directory(tmp_path, capsys):
    config = Config()
    config.i2c.lsm9ds1.odr_hz = 119.0
    path = record_drive(synthetic_drive(30.0), tmp_path / "logs", duration_s=2.5, config=config)
    record = last_diagnostics(path)
    assert set(record["sources"]) == {"can", "i2c", "gps"}
    cut = tmp_path / "cut" / path.name
    cut.parent.mkdir()
    cut.write_bytes(path.read_bytes()[:_just_after_the_first_diagnostics(path)])  # as the file being written
    assert last_diagnostics(cut) is not None
    toml = tmp_path / "logger.toml"
    toml.write_text(f'[logger]\ndirectory = "{tmp_path / "logs"}"\n')
    assert cli.main(["--config", str(toml), "--status"]) == 0
    out = capsys.readouterr().out
    assert path.name in out and "can" in out and "lsm9ds1" in out and "running" in out
    toml.write_text(f'[logger]\ndirectory = "{tmp_path / "empty"}"\n')
    assert cli.main(["--config", str(toml), "--status"]) == 1
    assert "no logs in" in capsys.readouterr().out


def test_current_marker_names_the_file_being_written(tmp_path):
    from haulprofile.logger.storage import LogDirectory, StorageOptions
    directory = LogDirectory(StorageOptions(tmp_path, min_free_bytes=0))
    first = directory.open()
    assert (tmp_path / ".current").read_text() == first.name + "\n"
    second = directory.open()
    assert (tmp_path / ".current").read_text() == second.name + "\n"
    directory.close()
    assert not (tmp_path / ".current").exists() and first.exists() and second.exists()
