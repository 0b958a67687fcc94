"""Landform statistics on analytic surfaces, the halves yardstick, and the comparison table."""
from __future__ import annotations

import math

import numpy as np
import pytest

from orokit.errors import InputError
from orokit.validate.landform import (
    FLOORS,
    compare_landforms,
    landform_distances,
    landform_statistics,
    spectral_slope,
    split_halves,
)


def _fbm(shape, res, beta, seed=0):
    """Random-phase surface whose power spectrum is exactly ``|k|^-beta`` (a sum of sinusoids)."""
    rng = np.random.default_rng(seed)
    ny, nx = shape
    ky = np.fft.fftfreq(ny, res)[:, None]
    kx = np.fft.rfftfreq(nx, res)[None, :]
    k = np.hypot(kx, ky)
    k[0, 0] = np.inf
    amp = k ** (-beta / 2.0)
    phase = rng.uniform(0, 2 * np.pi, amp.shape)
    return np.fft.irfft2(amp * np.exp(1j * phase), s=shape)


def test_plane_of_known_slope(make_dem):
    res, tan = 30.0, 0.1
    y, x = np.mgrid[0:100, 0:120]
    z = tan * x * res + 500.0
    st = landform_statistics(make_dem(z, res=res))
    assert st.cell_size_m == pytest.approx(res)
    assert np.allclose(st.slope_deg, math.degrees(math.atan(tan)), atol=1e-9)
    assert st.flat_share == 0.0
    assert np.allclose(st.curvature_per_km, 0.0, atol=1e-9)
    # hypsometry of a plane is uniform on [0, 1]: quantile u sits at u (to one column)
    u = (np.arange(st.hypsometry.size) + 0.5) / st.hypsometry.size
    assert np.abs(st.hypsometry - u).max() < 1.0 / 119 + 1e-9
    # 1 km window = 33 cells: interior relief 32 cells x 30 m x 0.1 = 96 m
    assert np.median(st.relief_1km) == pytest.approx(96.0)
    # all water leaves across the low (west) edge row by row: no cell drains > 1 km2
    assert st.drainage_share == 0.0 and st.drainage_density == 0.0


def test_flat_ground_is_flat(make_dem):
    st = landform_statistics(make_dem(np.full((40, 40), 12.0)))
    assert st.flat_share == 1.0 and st.slope_deg.max() == 0.0
    assert np.allclose(st.hypsometry, 0.0)


def test_cone(make_dem):
    """A cone of flank gradient s: slope atan(s) away from the apex, Laplacian -s / r."""
    res, s = 30.0, 0.5
    n = 121
    y, x = np.mgrid[0:n, 0:n]
    r = np.hypot(x - 60, y - 60) * res
    st = landform_statistics(make_dem(2000.0 - s * r, res=res))
    assert np.median(st.slope_deg) == pytest.approx(math.degrees(math.atan(s)), abs=0.2)
    # median of -s/r over the interior cells, in 1/km (r in m): compare with the hand value
    interior = np.zeros((n, n), bool)
    interior[1:-1, 1:-1] = True
    interior[60, 60] = False
    expected = np.median(-s / r[interior]) * 1000.0
    assert np.median(st.curvature_per_km) == pytest.approx(expected, rel=0.05)


@pytest.mark.parametrize("beta", [2.0, 3.0])
def test_spectral_slope_of_a_surface_with_known_spectrum(beta):
    res = 30.0
    z = _fbm((512, 512), res, beta, seed=1)
    assert spectral_slope(z, (res, res)) == pytest.approx(beta, abs=0.2)


def test_spectral_slope_ignores_scale_and_regional_tilt():
    """beta is a property of the shape of the spectrum: x 3 and a tilted plane change nothing;
    a grid smaller than the 0.5-10 km band gives NaN."""
    res = 50.0
    y, x = np.mgrid[0:300, 0:300]
    z = _fbm((300, 300), res, 2.4, seed=3)
    tilted = 3.0 * z + 0.05 * x * res - 0.02 * y * res
    assert spectral_slope(tilted, (res, res)) == pytest.approx(spectral_slope(z, (res, res)), abs=1e-6)
    assert np.isnan(spectral_slope(z[:5, :5], (res, res)))


def test_valley_drainage(make_dem):
    """A V-shaped valley draining south: the centre column carries (i + 1) rows of 61 cells."""
    res = 30.0
    ny, nx = 100, 61
    y, x = np.mgrid[0:ny, 0:nx]
    z = 0.3 * np.abs(x - 30) * res + 0.05 * (ny - y) * res
    st = landform_statistics(make_dem(z, res=res))
    row_area = nx * res * res
    channel_rows = int(np.sum((np.arange(ny) + 1) * row_area > 1.0e6))
    assert st.drainage_share == pytest.approx(channel_rows / z.size, abs=1.5 / z.size)
    dens = channel_rows * res / 1000.0 / (z.size * res * res / 1e6)
    assert st.drainage_density == pytest.approx(dens, rel=0.05)


def test_low_ground_sees_a_flat_basin_where_the_real_valley_is_a_gorge(make_dem):
    """Low ground = the slopes of the lowest tenth of the cells: a V valley's are its flanks' slope;
    the same valley filled to a flat floor at its base level has a flat lowest tenth, while the
    slope distribution over the whole grid barely moves."""
    res, ny, nx = 30.0, 100, 101
    y, x = np.mgrid[0:ny, 0:nx]
    v = 0.5 * np.abs(x - 50) * res + 0.01 * (ny - y) * res
    st = landform_statistics(make_dem(v, res=res))
    flank = math.degrees(math.atan(math.hypot(0.5, 0.01)))
    assert np.median(st.low_slope_deg) == pytest.approx(flank, abs=0.5)
    basin = np.maximum(v, np.quantile(v, 0.12))  # the lowest 12 % of the cells flat at one level
    t = compare_landforms(make_dem(v, res=res), make_dem(basin, res=res))
    assert np.median(landform_statistics(make_dem(basin, res=res)).low_slope_deg) < 2.0
    assert t.loc["low_slope_deg", "distance"] > 15.0 and not t.loc["low_slope_deg", "ok"]
    assert t.loc["slope_deg", "distance"] < 5.0  # the whole-grid slope distribution hardly sees it


def test_halves_yardstick_is_symmetric_and_zero_against_itself(make_dem):
    res = 30.0
    z = _fbm((200, 160), res, 2.6, seed=5)
    z = 1000 + 400 * z / z.std()
    dem = make_dem(z, res=res)
    north, south = (landform_statistics(h) for h in split_halves(dem))
    full = landform_statistics(dem)
    ab = landform_distances(north, south, relief_scale=full)
    ba = landform_distances(south, north, relief_scale=full)
    assert ab == ba
    # the yardstick of the DEM flipped north-south swaps the halves: same numbers
    flipped = make_dem(z[::-1].copy(), res=res)
    t1 = compare_landforms(dem, dem)
    t2 = compare_landforms(flipped, flipped)
    assert np.allclose(t1["halves"], t2["halves"], rtol=1e-9, atol=1e-12)
    assert (t1["distance"] == 0).all() and t1["ok"].all()
    assert set(FLOORS) <= set(t1.index)
    assert (t1.loc[list(FLOORS), "target"] >= pd_series(FLOORS)).all()


def pd_series(d):
    import pandas as pd

    return pd.Series(d)


def test_distance_grows_with_a_steeper_copy(make_dem):
    res = 30.0
    z = _fbm((128, 128), res, 2.5, seed=7)
    z = 800 + 200 * z / z.std()
    real = make_dem(z, res=res)
    steep = make_dem(800 + 3 * (z - 800), res=res)
    t = compare_landforms(real, steep)
    assert t.loc["slope_deg", "distance"] > 5.0 and not t.loc["slope_deg", "ok"]
    rq = landform_statistics(real).relief_1km  # 3 x the relief: W1 = mean(2 r), over the real median
    assert t.loc["relief_1km", "distance"] == pytest.approx(2.0 * rq.mean() / np.median(rq), rel=1e-9)
    assert t.loc["hypsometry", "distance"] < 1e-9  # a linear map keeps the normalised elevations


def test_cell_sizes_must_match(make_dem):
    z = np.random.default_rng(0).random((40, 40)) * 100
    with pytest.raises(InputError, match="same cell size"):
        compare_landforms(make_dem(z, res=30.0), make_dem(z, res=90.0))


def test_lonlat_grid_uses_ground_cell_sizes(make_dem):
    """The same plane on a lon/lat grid at 60 deg N: slopes from metre cell sizes."""
    res_deg = 1.0 / 1200.0
    lat0 = 60.0
    dy_m = 6_371_000 * math.radians(res_deg)  # about 92.6 m
    y, x = np.mgrid[0:60, 0:60]
    z = 0.2 * (59 - y) * dy_m  # rises to the north
    dem = make_dem(z, res=res_deg, crs="EPSG:4326", origin=(10.0, lat0 + 30 * res_deg))
    st = landform_statistics(dem)
    assert np.median(st.slope_deg) == pytest.approx(math.degrees(math.atan(0.2)), abs=0.3)


def test_validate_prints_and_records_the_landform_table(tmp_path, make_dem):
    """`orokit validate RASTER --tree T --real DEM` prints every landform distance and writes them."""
    import json

    from click.testing import CliRunner

    from orokit.cli.main import cli
    from orokit.io.divide_tree_io import write_divide_tree_gpkg
    from orokit.io.raster_io import write_cog
    from orokit.raster.render import render_elevation
    from orokit.topology.divide_tree import DivideTree

    tree = DivideTree.from_arrays([[1000.0, 1000.0, 600.0], [3000.0, 1000.0, 550.0]], [[2000.0, 1000.0, 450.0]],
                                  [[0, 1, 0]], attrs={"extent": [0.0, 0.0, 4000.0, 2000.0]})
    dem = render_elevation(tree, cell_size_m=50.0, erosion=False, rng=1)
    write_cog(dem, tmp_path / "dem.tif")
    write_divide_tree_gpkg(tree, tmp_path / "tree.gpkg")
    z = 500 + 60 * _fbm((40, 80), 50.0, 2.5, seed=2)
    real = make_dem(z / z.std() * 40 + 500, res=50.0, crs=None)
    real.attrs["units"] = "m"
    write_cog(real, tmp_path / "real.tif")
    r = CliRunner().invoke(cli, ["validate", str(tmp_path / "dem.tif"), "--tree", str(tmp_path / "tree.gpkg"),
                                 "--real", str(tmp_path / "real.tif"), "-o", str(tmp_path / "v.json")])
    assert r.exit_code == 0, r.output
    for stat in FLOORS:
        assert stat in r.output
    doc = json.loads((tmp_path / "v.json").read_text())
    rows = {row["statistic"]: row for row in doc["landform"]["table"]}
    assert set(FLOORS) <= set(rows)
    assert all(np.isfinite(rows[s]["distance"]) for s in FLOORS if s != "spectral_slope")


def test_band_power_puts_a_wave_in_its_band_and_scales_with_amplitude():
    """A sinusoid's power lands in the band holding its wavelength; doubling the amplitude
    quadruples every band; a band longer than the grid has no wavenumber (NaN)."""
    from orokit.validate.landform import POWER_BANDS_M, band_power

    res = 50.0
    y, x = np.mgrid[0:256, 0:256] * res
    for i, wave in ((0, 200.0), (2, 800.0), (4, 3200.0)):
        lo, hi = POWER_BANDS_M[i]
        assert lo <= wave < hi
        z = 10.0 * np.sin(2 * np.pi * (x + 0.3 * y) / wave)
        p = band_power(z, (res, res))
        assert int(np.nanargmax(p)) == i
        assert np.allclose(band_power(2.0 * z, (res, res)), 4.0 * p, rtol=1e-9, atol=1e-12)
    p = band_power(np.random.default_rng(0).standard_normal((64, 80)), (res, res))  # 3.2 x 4 km
    assert np.isfinite(p[:-1]).all() and np.isnan(p[-1])
    assert np.isnan(band_power(np.full((8, 8), np.nan), (res, res))).all()


@pytest.mark.parametrize("tan", [0.1, 2.0])
def test_channel_slopes_of_a_tilted_plane(make_dem, tan):
    """A plane falling west at ``tan`` m/m: every interior cell drains west along its row (the border cells are
    outlets: column j of 400 drains 399 - j cells), so every channel's slope is ``tan`` and the bands hold the cells of
    their areas; steeper than 1 m/m: all or none."""
    from orokit.metrics.landform import channel_slopes

    res = 30.0
    y, x = np.mgrid[0:12, 0:400]
    got = channel_slopes(make_dem(tan * x * res + 500.0, res=res), bands_km2=((0.1, 1.0), (1.0, 10.0)))
    band = got["0.1-1"]
    area = (399 - np.arange(1, 399)) * res**2
    assert band["n"] == 10 * int(np.sum((area >= 0.1e6) & (area < 1.0e6)))
    assert band["p10"] == pytest.approx(tan) and band["p99"] == pytest.approx(tan)
    assert band["steep_share"] == (1.0 if tan > 1.0 else 0.0)
    assert got["1-10"]["n"] == 0 and math.isnan(got["1-10"]["p50"])
