import numpy as np
import pytest

from haulprofile.analysis.dem.srtm import MissingTileError, SrtmDem, read_hgt, tile_name, write_hgt


def test_tile_names():
    assert tile_name(50.7, 6.1) == "N50E006"
    assert tile_name(-0.5, -70.2) == "S01W071"


def test_write_read_and_bilinear(tmp_path):
    n = 1201
    lat_idx, lon_idx = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    heights = 100.0 + 0.5 * lon_idx + 0.25 * (n - 1 - lat_idx)  # linear plane: bilinear is exact
    heights[5, 5] = np.nan
    write_hgt(tmp_path / "N50E006.hgt", heights)
    back = read_hgt(tmp_path / "N50E006.hgt")
    assert np.isnan(back[5, 5])
    dem = SrtmDem(tmp_path)
    lat, lon = np.array([50.5, 50.123]), np.array([6.5, 6.789])
    expected = 100 + 0.5 * (lon - 6) * 1200 + 0.25 * (lat - 50) * 1200
    np.testing.assert_allclose(dem.height_m(lat, lon), np.round(expected), atol=1.0)
    with pytest.raises(MissingTileError, match="N51E006"):
        dem.height_m([51.2], [6.0])
