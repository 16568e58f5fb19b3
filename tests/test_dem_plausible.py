"""A DEM tile of the right size but the wrong content is refused, naming the tile; map gradients
steeper than any road are left out of the fusion."""

import numpy as np
import pandas as pd
import pytest

from haulprofile.analysis import cli
from haulprofile.analysis.dem.plausible import ImplausibleDemError, check_heights
from haulprofile.analysis.dem.srtm import read_hgt, write_hgt


def test_random_bytes_of_a_tiles_size_are_not_terrain(tmp_path):
    tile = tmp_path / "N50E006.hgt"
    tile.write_bytes(np.random.default_rng(0).bytes(1201 * 1201 * 2))
    with pytest.raises(ImplausibleDemError, match="N50E006.hgt"):
        read_hgt(tile)


def test_terrain_passes_and_noise_within_the_range_does_not():
    rows, cols = np.mgrid[0:1201, 0:1201]
    hills = 400 + 150 * np.sin(rows / 90) * np.cos(cols / 70)
    assert check_heights(hills, "hills") is hills
    noise = np.random.default_rng(1).uniform(0, 3000, (1201, 1201))
    with pytest.raises(ImplausibleDemError, match="noise"):
        check_heights(noise, "noise tile")


def test_wrong_byte_order_is_refused(tmp_path):
    rows, cols = np.mgrid[0:1201, 0:1201]
    tile = write_hgt(tmp_path / "N50E006.hgt", 300 + 0.1 * rows + 0.05 * cols)
    swapped = np.fromfile(tile, ">i2").astype("<i2")
    swapped.tofile(tile)
    with pytest.raises(ImplausibleDemError):
        read_hgt(tile)


def test_analyze_run_with_a_random_tile_is_one_line(tmp_path, capsys):
    tile = tmp_path / "dem" / "N50E006.hgt"
    tile.parent.mkdir()
    tile.write_bytes(np.random.default_rng(2).bytes(1201 * 1201 * 2))
    time = np.arange(3000) * 0.1
    table = tmp_path / "drive.csv"
    pd.DataFrame({"time_s": time, "speed_mps": np.full(3000, 15.0), "latitude_deg": 50.5 + time * 1e-5,
                  "longitude_deg": np.full(3000, 6.5), "gps_h_acc_m": 2.0, "gps_v_acc_m": 3.0,
                  "pressure_pa": 95_000.0 - time * 0.1}).to_csv(table, index=False)
    code = cli.main(["run", str(table), "--vehicle", "rigid-18t", "--dem", str(tile.parent),
                     "--out", str(tmp_path / "out"), "--candidates", "10", "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and "N50E006.hgt" in err and len(err.strip().splitlines()) == 1, err


def test_map_gradients_steeper_than_a_road_are_left_out_of_the_fusion():
    from haulprofile.analysis.gradient.estimate import _fuse

    s_grid = np.arange(10) * 10.0
    map_slope = np.full(10, 0.02)
    map_slope[4:6] = [1.8, -3.6]
    notes = []
    fused = _fuse(map_slope, np.ones(10), np.full(10, 0.03), s_grid, notes)
    assert np.all(np.abs(fused) < 0.05) and fused[4] == pytest.approx(0.03)
    assert any("above 30 %" in n for n in notes)
