"""The FASTSim 3 cycle file: read by FASTSim itself, its distance and elevation (which FASTSim
integrates from speed and grade) against ours, and simulated by FASTSim."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from haulprofile.analysis.export.fastsim import fastsim_cycle, write_fastsim_cycle
from haulprofile.analysis.markov.export import write_cycle
from haulprofile.analysis.vecto import vdri_to_time_cycle
from haulprofile.analysis.vecto import read_vdri
from haulprofile.testing.drives import synthetic_drive

fastsim = pytest.importorskip("fastsim", reason="FASTSim is not installed (pip install fastsim; the bench extra)")


@pytest.fixture(scope="module")
def regional(data_dir) -> pd.DataFrame:
    """VECTO's RegionalDelivery mission as a 1 Hz trace, with its hills."""
    return vdri_to_time_cycle(read_vdri(data_dir / "vecto-cycles" / "RegionalDelivery.vdri"))


def test_fastsim_reads_time_speed_and_grade(tmp_path, regional):
    path = write_fastsim_cycle(regional, tmp_path / "cycle.fastsim.csv")
    cycle = fastsim.Cycle.from_file(str(path)).to_dict()
    np.testing.assert_allclose(cycle["time_seconds"], regional["time_s"] - regional["time_s"].iloc[0])
    np.testing.assert_allclose(cycle["speed_meters_per_second"], regional["speed_mps"], atol=1e-8)
    np.testing.assert_allclose(cycle["grade"], regional["gradient_pct"] / 100.0, atol=1e-10)
    # FASTSim integrates distance itself (each second at the speed reached at its end)
    expected = np.concatenate([[0.0], np.cumsum(regional["speed_mps"].to_numpy()[1:] * np.diff(regional["time_s"]))])
    np.testing.assert_allclose(cycle["dist_meters"], expected, rtol=1e-9, atol=1e-6)
    ours = regional["distance_m"].to_numpy() - regional["distance_m"].iloc[0]
    assert cycle["dist_meters"][-1] == pytest.approx(ours[-1], rel=0.01)
    climb = np.cumsum(np.diff(cycle["dist_meters"]) * np.sin(np.arctan(regional["gradient_pct"].to_numpy()[1:] / 100)))
    np.testing.assert_allclose(np.asarray(cycle["elev_meters"][1:]) - cycle["elev_meters"][0], climb, atol=1e-6)
    assert np.ptp(cycle["elev_meters"]) > 20.0  # the mission's hills reached FASTSim


def test_fastsim_simulates_the_exported_cycle(tmp_path):
    """A drive (not VECTO's target speeds, which step by 12 m/s in a second) simulated by FASTSim
    with one of its own vehicles: it follows the trace."""
    drive_1hz = synthetic_drive(1200.0, seed=2, kind="regional")
    path = write_fastsim_cycle(drive_1hz, tmp_path / "cycle.fastsim.csv")
    vehicle = fastsim.Vehicle.from_resource("2022_Renault_Zoe_ZE50_R135.yaml")
    drive = fastsim.SimDrive(vehicle, fastsim.Cycle.from_file(str(path)))
    drive.run()
    trace = drive.to_dataframe()
    achieved = trace.filter(like="speed_ach").iloc[:, 0].to_numpy()
    assert len(achieved) == len(drive_1hz)
    assert np.max(np.abs(achieved - drive_1hz["speed_mps"].to_numpy())) < 0.5
    soc = trace["veh.pt_type.BEV.res.history.soc"].to_numpy()
    assert 0.0 < soc[0] - soc[-1] < 0.5
    assert trace["veh.history.energy_ascent_joules"].abs().max() > 0  # the grade went into the simulation


def test_cycle_files_include_the_fastsim_cycle(tmp_path, regional):
    paths = write_cycle(regional.assign(accel_mps2=0.0, mass_kg=20_000.0), tmp_path)
    assert paths["fastsim"].name == "cycle.fastsim.csv"
    assert list(pd.read_csv(paths["fastsim"]).columns) == list(fastsim_cycle(regional).columns)
