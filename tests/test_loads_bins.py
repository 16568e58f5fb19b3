"""Load collectives on fixed bins: drives sum bin by bin, and the fleet's sums are the same bins."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from haulprofile.analysis.errors import UserError
from haulprofile.analysis.fleet.statistics import LoadBins, log_statistics
from haulprofile.analysis.loads import collectives_of
from haulprofile.analysis.loads.bins import (WIDTHS, apply_overrides, class_edges, default_edges, read_overrides,
                                             vehicle_class)
from haulprofile.analysis.vehicle import load_vehicle
from haulprofile.testing.drives import synthetic_drive


def drive(seed: int, duration_s: float = 900.0) -> pd.DataFrame:
    """A 1 Hz drive (the fleet counts on 1 s means, so both count the same samples)."""
    frame = synthetic_drive(duration_s, seed=seed, kind="regional")
    frame["accel_mps2"] = np.gradient(frame["speed_mps"].to_numpy(), frame["time_s"].to_numpy())
    return frame


@pytest.fixture(scope="module")
def rigid():
    return load_vehicle("rigid-18t")


def test_classes_and_edges_are_on_the_width_grid(rigid):
    assert vehicle_class(rigid) == "rigid" and vehicle_class(load_vehicle("tractor-40t")) == "articulated"
    for name in ("rigid", "articulated"):
        for axis, edges in class_edges(name).arrays().items():
            steps = edges / WIDTHS[axis]
            np.testing.assert_array_equal(steps, np.round(steps))
            np.testing.assert_allclose(np.diff(edges), WIDTHS[axis])


def test_drives_counted_alone_sum_to_the_drives_counted_together(rigid):
    a, b = drive(1), drive(2)
    alone = [collectives_of({"d": d}, rigid)["d"] for d in (a, b)]
    b_later = b.assign(time_s=b["time_s"] + a["time_s"].iloc[-1] + 1.0)
    together = collectives_of({"d": pd.concat([a, b_later], ignore_index=True)}, rigid)["d"]
    for quantity in ("wheel_force_n", "wheel_torque_nm", "wheel_speed_rpm", "wheel_power_w"):
        np.testing.assert_array_equal(alone[0].edges[quantity], together.edges[quantity])
        # the joined drive's one extra interval (0.5 s each side of the join) is the only difference
        summed = alone[0].time_at_level[quantity] + alone[1].time_at_level[quantity]
        assert np.abs(together.time_at_level[quantity] - summed).sum() == pytest.approx(1.0)
    np.testing.assert_allclose(alone[0].residence_s.sum() + alone[1].residence_s.sum() + 1.0,
                               together.residence_s.sum())


def test_the_fleet_sums_on_the_same_bins(rigid):
    logs = [drive(1), drive(2)]
    fleet = log_statistics("a", logs[0], {}, rigid) + log_statistics("b", logs[1], {}, rigid)
    drives = [collectives_of({"d": d}, rigid)["d"] for d in logs]
    edges = default_edges(rigid).arrays()
    for quantity in ("wheel_force_n", "wheel_torque_nm", "wheel_speed_rpm", "wheel_power_w"):
        histogram = fleet.histograms[f"time_at_level_{quantity}"]
        assert histogram.widths == (WIDTHS[quantity],)
        first = int(round(edges[quantity][0] / WIDTHS[quantity]))
        dense = np.zeros(len(edges[quantity]) - 1)
        dense[histogram.keys[:, 0] - first] = histogram.values  # every sample lies inside the class's range
        np.testing.assert_allclose(dense, drives[0].time_at_level[quantity] + drives[1].time_at_level[quantity],
                                   rtol=1e-12, atol=1e-9)
    residence = fleet.histograms["residence_speed_torque_s"]
    assert residence.widths == (WIDTHS["residence_speed_rpm"], WIDTHS["residence_torque_nm"])
    rows = residence.keys[:, 0] - int(round(edges["residence_speed_rpm"][0] / WIDTHS["residence_speed_rpm"]))
    columns = residence.keys[:, 1] - int(round(edges["residence_torque_nm"][0] / WIDTHS["residence_torque_nm"]))
    dense = np.zeros_like(drives[0].residence_s)
    dense[rows, columns] = residence.values
    np.testing.assert_allclose(dense, drives[0].residence_s + drives[1].residence_s, rtol=1e-12, atol=1e-9)
    crossings = fleet.histograms["level_crossings_torque"]
    levels = dict(zip((crossings.keys[:, 0] * WIDTHS["wheel_torque_nm"]).tolist(), crossings.values.tolist()))
    summed = drives[0].crossings + drives[1].crossings
    for level, count in zip(drives[0].crossing_levels_nm.tolist(), summed.tolist()):
        assert levels.get(level, 0.0) == count
    assert LoadBins().rainflow_nm == WIDTHS["rainflow_range_nm"]


def test_bins_are_overridable_from_a_file(tmp_path, rigid):
    path = tmp_path / "bins.toml"
    path.write_text("[wheel_torque_nm]\nlow = -20000\nhigh = 40000\nwidth = 1000\n")
    edges = apply_overrides(default_edges(rigid), read_overrides(path))
    np.testing.assert_array_equal(edges.wheel_torque_nm.edges(), np.arange(-20000, 40001, 1000.0))
    assert edges.wheel_force_n == default_edges(rigid).wheel_force_n
    path.write_text("[wheel_torque_nm]\nlow = -20250\n")
    with pytest.raises(UserError, match="not a multiple of width"):
        read_overrides(path)
    path.write_text("[torque]\nlow = 0\n")
    with pytest.raises(UserError, match="unknown table"):
        read_overrides(path)


def test_analyze_loads_takes_a_bins_file(tmp_path, rigid):
    from haulprofile.analysis.cli import main

    drive(600, 1).to_parquet(tmp_path / "signals.parquet")
    (tmp_path / "bins.toml").write_text("[wheel_speed_rpm]\nhigh = 300\nwidth = 20\n")
    assert main(["loads", str(tmp_path / "signals.parquet"), "--vehicle", "rigid-18t", "--load-bins",
                 str(tmp_path / "bins.toml"), "--out", str(tmp_path / "o")]) == 0
    table = pd.read_csv(tmp_path / "o" / "measured_time_at_level_wheel_speed_rpm.csv")
    assert table.columns.tolist() == ["wheel_speed_rpm_low", "wheel_speed_rpm_high", "time_s"]
    np.testing.assert_array_equal(table["wheel_speed_rpm_low"], np.arange(0, 300, 20.0))
    residence = pd.read_csv(tmp_path / "o" / "measured_residence_speed_torque_s.csv")
    assert residence.columns[0] == "wheel_speed_rpm \\ wheel_torque_nm"
    assert residence.columns[1] == "-75000..-72500 Nm" and residence.iloc[0, 0] == "0..25 rpm"
