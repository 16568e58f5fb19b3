import pandas as pd
import pytest

from haulprofile.analysis.signals import SignalsError, read_signals, write_signals


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_round_trip_keeps_unknown_columns(tmp_path, suffix):
    frame = pd.DataFrame({"time_s": [0.0, 0.1], "speed_mps": [1.0, 1.1], "my_sensor": [3, 4]})
    back = read_signals(write_signals(frame, tmp_path / f"s{suffix}"))
    pd.testing.assert_frame_equal(back, frame, check_dtype=False)


def test_missing_speed_is_one_clear_line(tmp_path):
    path = write_signals(pd.DataFrame({"time_s": [0.0], "velocity": [1.0]}), tmp_path / "s.csv")
    with pytest.raises(SignalsError) as info:
        read_signals(path)
    assert "speed_mps" in str(info.value) and "\n" not in str(info.value)
