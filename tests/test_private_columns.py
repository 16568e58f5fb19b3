"""``--private`` keeps every column that tells where or when out of the signals table: ours, a
foreign CSV's (``lat``, ``lon``, ``gps_time_utc``) and DBC-decoded ones (Vehicle Position,
Time/Date), at full precision before."""

import pandas as pd
import pytest

from haulprofile.analysis.outputs import write_outputs
from haulprofile.analysis.pipeline import RunContext
from haulprofile.analysis.signals import is_position_column

FOREIGN = ["lat", "lon", "gps_time_utc", "Latitude", "Longitude", "VP_Latitude", "dbc_Longitude", "Hours",
           "Minutes", "Seconds", "Day", "Month", "Year"]
KEPT = ["time_s", "speed_mps", "height_m", "gps_altitude_m", "gps_h_acc_m", "EngineSpeed",
        "EngineTotalHoursOfOperation", "accel_long_mps2"]


@pytest.mark.parametrize("name", FOREIGN + ["latitude_deg", "longitude_deg", "wall_time_ns"])
def test_position_and_clock_columns_are_recognised(name):
    assert is_position_column(name)


@pytest.mark.parametrize("name", KEPT)
def test_other_columns_are_not(name):
    assert not is_position_column(name)


def test_private_output_step_drops_foreign_and_dbc_positions(tmp_path):
    frame = pd.DataFrame({name: [0.0, 1.0] for name in KEPT + FOREIGN + ["latitude_deg", "longitude_deg"]})
    frame["lat"], frame["lon"] = [48.1234567, 48.1234568], [11.5654321, 11.5654322]
    ctx = RunContext(inputs=[], out_dir=tmp_path, signals=frame,
                     options={"output": {"private": True, "signals_file": "s.parquet"}}, say=print)
    write_outputs(ctx, [], full=False)
    assert list(pd.read_parquet(tmp_path / "s.parquet")) == KEPT
