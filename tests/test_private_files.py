"""Logs and analysis outputs that hold positions are 0640 in 0750 directories, whatever the umask."""

from __future__ import annotations

import os
import stat

import pandas as pd
import pytest

from haulprofile.analysis.outputs import write_outputs
from haulprofile.analysis.pipeline import RunContext
from haulprofile.logger.storage import LogDirectory, StorageOptions
from haulprofile.contract.private_files import make_dirs, restrict_tree


def mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


@pytest.fixture(params=[0o000, 0o022, 0o077])
def umask(request):
    old = os.umask(request.param)
    yield request.param
    os.umask(old)


def test_logger_files_and_directories(tmp_path, umask):
    directory = tmp_path / "var" / "logs"
    storage = LogDirectory(StorageOptions(directory=directory, fsync=False, min_free_bytes=0),
                           header_metadata={"boot_id": "x"})
    first = storage.open()
    second = storage.open()
    storage.close()
    assert mode(tmp_path / "var") == mode(directory) == 0o750
    assert mode(first) == mode(second) == 0o640
    assert mode(directory / ".sequence") == 0o640


def test_signals_table_and_output_tree(tmp_path, umask):
    frame = pd.DataFrame({"time_s": [0.0, 0.1], "latitude_deg": [48.1, 48.1], "longitude_deg": [11.5, 11.5]})
    for name in ("a/signals.parquet", "b/signals.csv"):  # the output step, as `analyze signals -o`
        path = tmp_path / name
        write_outputs(RunContext(inputs=[], out_dir=path.parent, signals=frame,
                                 options={"output": {"signals_file": path.name}}, say=print), [], full=False)
        assert mode(path) == 0o640 and mode(path.parent) == 0o750
    out = make_dirs(tmp_path / "out" / "run")
    (out / "figures").mkdir(mode=0o777)
    (out / "figures" / "map.png").write_bytes(b"png")
    os.chmod(out / "figures" / "map.png", 0o666)
    restrict_tree(out)
    assert mode(out / "figures") == 0o750 and mode(out / "figures" / "map.png") == 0o640


def test_private_output_step_writes_no_positions(tmp_path):
    frame = pd.DataFrame({"time_s": [0.0, 0.1], "latitude_deg": [48.1, 48.1], "longitude_deg": [11.5, 11.5],
                          "wall_time_ns": [1, 2], "height_m": [500.0, 500.1]})
    ctx = RunContext(inputs=[], out_dir=tmp_path, signals=frame,
                     options={"output": {"private": True, "signals_file": "s.parquet"}}, say=print)
    write_outputs(ctx, [], full=False)
    assert list(pd.read_parquet(tmp_path / "s.parquet")) == ["time_s", "height_m"]
