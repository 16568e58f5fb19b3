"""The Python API: every advertised name resolves, and ``analysis.run`` returns what the CLI writes."""

import pandas as pd
import pytest

from haulprofile import analysis
from haulprofile.analysis.vehicle import load_vehicle
from haulprofile.analysis.virtual_truck import drive, load_scenario


@pytest.mark.parametrize("name", analysis.__all__)
def test_every_export_resolves(name):
    assert callable(getattr(analysis, name))


def test_run_until_a_stage_returns_dataframes(tmp_path):
    truth = drive(load_scenario("long-haul"), load_vehicle("tractor-40t"), seed=1).truth
    path = tmp_path / "drive.parquet"
    truth.drop(columns=["mass_kg"]).to_parquet(path)
    result = analysis.run(path, vehicle="tractor-40t", out=tmp_path / "out", until="mass")
    assert isinstance(result.signals, pd.DataFrame) and "mass_kg" in result.signals
    segments = result.mass_segments
    assert (segments["status"] == "ok").any()
    ok = segments[segments["status"] == "ok"]
    true_mass = truth["mass_kg"].median()
    assert (abs(ok["mass_ls_kg"] - true_mass) / true_mass).median() < 0.03
    assert result.cycle is None
    assert not (tmp_path / "out" / "summary.json").exists()


def test_option_tables_reach_the_settings_that_hold_them_and_unknown_keys_are_one_line():
    from haulprofile.analysis.errors import UserError

    options = analysis.Options.of({"mass": {"forgetting_factor": 0.99}, "mass_filter": {"min_speed_mps": 3.0},
                                   "cycle": {"widths": {"mass_kg": 200.0}, "seed": 4},
                                   "simulation": {"time_step_s": 0.05, "payload_kg": 6000}})
    assert options.mass.segments.forgetting_factor == 0.99 and options.mass.filter.min_speed_mps == 3.0
    assert options.cycle.widths.mass_kg == 200.0 and options.cycle.seed == 4
    assert options.simulation.driver.time_step_s == 0.05 and options.simulation.payload_kg == 6000
    with pytest.raises(UserError, match="unknown key 'n_candidate'") as error:
        analysis.Options.of({"cycle": {"n_candidate": 5}})
    assert "\n" not in str(error.value)
    with pytest.raises(UserError, match="no stage named cycles"):
        analysis.Options.of({"cycles": {}})
