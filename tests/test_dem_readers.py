import numpy as np
import pytest

from haulprofile.analysis.dem import MissingTileError, open_dem
from haulprofile.analysis.dem.bilinear import bilinear_m
from haulprofile.analysis.dem.srtm import SrtmDem, write_hgt
from haulprofile.analysis.errors import UserError


def plane_m(lat, lon):
    return 200.0 + 1000.0 * (lat - 47.0) + 500.0 * (lon - 11.0)


def test_one_arcsecond_tile_is_exact_on_a_plane(tmp_path):
    n = 3601
    lat = 48.0 - np.arange(n) / (n - 1)
    lon = 11.0 + np.arange(n) / (n - 1)
    write_hgt(tmp_path / "N47E011.hgt", plane_m(lat[:, None], lon[None, :]))
    dem = open_dem(tmp_path)
    assert isinstance(dem, SrtmDem)
    q_lat, q_lon = np.array([47.25, 47.9]), np.array([11.5, 11.01])
    np.testing.assert_allclose(dem.height_m(q_lat, q_lon), plane_m(q_lat, q_lon), atol=0.5)


def test_void_corner_is_left_out_not_propagated():
    grid = np.array([[0.0, 10.0], [20.0, np.nan]])
    assert bilinear_m(grid, np.array([0.5]), np.array([0.5]))[0] == pytest.approx(10.0)  # (0+10+20)/3
    assert np.isnan(bilinear_m(np.full((2, 2), np.nan), np.array([0.5]), np.array([0.5])))[0]
    assert np.isnan(bilinear_m(grid, np.array([1.5]), np.array([0.0])))[0]


def test_empty_or_missing_directory_is_a_user_error(tmp_path):
    with pytest.raises(UserError, match="no SRTM"):
        open_dem(tmp_path)
    with pytest.raises(UserError, match="not found"):
        open_dem(tmp_path / "nope")


def _write_geotiff(path, crs, transform, heights, nodata=-9999.0):
    rasterio = pytest.importorskip("rasterio")
    with rasterio.open(path, "w", driver="GTiff", width=heights.shape[1], height=heights.shape[0], count=1,
                       dtype="float32", crs=crs, transform=transform, nodata=nodata) as dst:
        dst.write(np.where(np.isfinite(heights), heights, nodata).astype("float32"), 1)


def test_geographic_geotiff_bilinear_and_coverage(tmp_path):
    rasterio = pytest.importorskip("rasterio")
    step = 1 / 3600
    rows, cols = 400, 500
    transform = rasterio.Affine(step, 0.0, 11.0, 0.0, -step, 47.1)
    lat_c = 47.1 - (np.arange(rows) + 0.5) * step
    lon_c = 11.0 + (np.arange(cols) + 0.5) * step
    heights = plane_m(lat_c[:, None], lon_c[None, :])
    heights[10, 10] = np.nan
    _write_geotiff(tmp_path / "dem.tif", "EPSG:4326", transform, heights)
    dem = open_dem(tmp_path)
    q_lat, q_lon = np.array([47.05, 47.0301]), np.array([11.1, 11.1234])
    np.testing.assert_allclose(dem.height_m(q_lat, q_lon), plane_m(q_lat, q_lon), atol=1e-3)
    near_void = dem.height_m(lat_c[10] - 0.3 * step, lon_c[10] + 0.2 * step)[0]
    assert near_void == pytest.approx(plane_m(lat_c[10] - 0.3 * step, lon_c[10] + 0.2 * step), abs=0.1)
    with pytest.raises(MissingTileError, match="leaves the DEM"):
        dem.height_m([47.5], [11.1])


def test_projected_geotiff_is_looked_up_in_its_own_crs(tmp_path):
    rasterio = pytest.importorskip("rasterio")
    from rasterio.warp import transform as warp
    x0, y0 = warp("EPSG:4326", "EPSG:32632", [11.0], [47.0])
    res = 25.0
    transform = rasterio.Affine(res, 0.0, x0[0] - 2000, 0.0, -res, y0[0] + 2000)
    xs = x0[0] - 2000 + (np.arange(160) + 0.5) * res
    ys = y0[0] + 2000 - (np.arange(160) + 0.5) * res
    heights = 300.0 + 0.01 * (xs[None, :] - x0[0]) - 0.02 * (ys[:, None] - y0[0])
    _write_geotiff(tmp_path / "utm.tiff", "EPSG:32632", transform, heights)
    q_lon, q_lat = np.array([11.0, 11.005]), np.array([47.0, 46.995])
    qx, qy = warp("EPSG:4326", "EPSG:32632", q_lon, q_lat)
    expected = 300.0 + 0.01 * (np.array(qx) - x0[0]) - 0.02 * (np.array(qy) - y0[0])
    np.testing.assert_allclose(open_dem(tmp_path).height_m(q_lat, q_lon), expected, atol=1e-3)
