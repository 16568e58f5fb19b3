"""The signals table validator names the real fault; the same log or table given twice counts once."""

import shutil

import numpy as np
import pandas as pd
import pytest

from haulprofile.analysis import cli
from haulprofile.analysis.ingest import ingest_logs
from haulprofile.testing import logs as synthetic
from haulprofile.analysis.signals import SignalsError, validate


def frame(time, speed):
    return pd.DataFrame({"time_s": np.asarray(time, float), "speed_mps": np.asarray(speed, float)})


@pytest.mark.parametrize("time, speed, fault", [
    ([0, 0.1, 0.2], [1, -3, 2], "negative"),
    ([0, 0.1, 0.2], [1, 1e9, 2], "1e+09 m/s"),
    ([0, 0.2, 0.1], [1, 2, 3], "goes backwards at row 2"),
    ([0, 0.1, 0.1, 0.2], [1, 2, 3, 4], "duplicated time stamp"),
    ([0, 0.1, 0.2], [np.nan] * 3, "speed_mps has no values"),
    ([0], [1], "single row"),
])
def test_each_fault_is_named(time, speed, fault):
    with pytest.raises(SignalsError, match=fault.replace("+", r"\+")):
        validate(frame(time, speed))


def test_duplicated_time_stamps_are_not_called_a_rising_time_in_simulate(tmp_path, capsys):
    path = tmp_path / "cycle.csv"
    frame([0, 1, 1, 2], [1, 2, 3, 4]).to_csv(path, index=False)
    assert cli.main(["simulate", str(path), "--vehicle", "rigid-18t", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "duplicated time stamp" in err and "rise strictly" not in err


def test_a_table_given_twice_counts_once(tmp_path):
    time = np.arange(100) * 0.1
    path = tmp_path / "a.csv"
    frame(time, np.full(100, 10.0)).to_csv(path, index=False)
    shutil.copy(path, tmp_path / "copy.csv")
    said = []
    joined, summary = ingest_logs([path, path, tmp_path / "copy.csv"], say=said.append)
    assert len(joined) == 100 and summary["duration_s"] == pytest.approx(10.0)
    assert sum("same content" in s for s in said) == 2


def test_three_copies_of_a_log_in_a_directory_count_once(tmp_path):
    with open(tmp_path / "a.mcap", "wb") as stream:
        synthetic.write_log(stream, 5, seed=1)
    for name in ("b.mcap", "c.mcap"):
        shutil.copy(tmp_path / "a.mcap", tmp_path / name)
    said = []
    table, summary = ingest_logs([tmp_path], say=said.append)
    assert len(table) == 50 and summary["valid_fraction"] == 1.0
    assert len(summary["inputs"]) == 1 and sum("same content" in s for s in said) == 2
