"""Prominence under DEM error (issue 16): bounds, Monte Carlo, correlated noise, CLI."""
from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

import orokit
from orokit.errors import InputError
from orokit.topology.uncertainty import correlated_noise, monte_carlo, prominence_bounds


def _bumps(seed: int = 0, n: int = 6, size: int = 120) -> tuple[np.ndarray, np.ndarray]:
    """Gaussian hills of distinct heights (>= 40 m apart) on a tilted plane, far apart."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:size, 0:size].astype(float)
    z = 0.05 * yy
    heights = 100.0 + 40.0 * rng.permutation(n)
    centres = [(20 + 40 * (i // 3), 20 + 40 * (i % 3)) for i in range(n)]
    for (r, c), h in zip(centres, heights):
        z += h * np.exp(-((yy - r) ** 2 + (xx - c) ** 2) / (2 * 6.0 ** 2))
    return z, heights


def test_bounds_analytic():
    lo, hi = prominence_bounds(np.array([10.0, 1.0, 500.0]), np.array([False, False, True]), 1.5, k=3)
    np.testing.assert_allclose(lo, [1.0, 0.0, 495.5])
    np.testing.assert_allclose(hi, [19.0, 10.0, 504.5])
    with pytest.raises(InputError, match="sigma"):
        prominence_bounds(np.array([1.0]), np.array([False]), -1.0)


def test_sigma_zero_gives_point_values(make_dem):
    z, _ = _bumps()
    r = orokit.analyze(make_dem(z), min_prominence_m=20, isolation=False, dem_error_m=0.0, samples=3, seed=1)
    p = r.peaks
    assert len(p) == 6
    np.testing.assert_array_equal(p["prominence_low"], p["prominence"])
    np.testing.assert_array_equal(p["prominence_high"], p["prominence"])
    np.testing.assert_array_equal(p["p_exists"], 1.0)
    np.testing.assert_array_equal(p["prominence_median"], p["prominence"])


def test_monte_carlo_samples_within_bounds_and_reproducible():
    """Every realisation whose error stays within k sigma gives prominences inside the bounds."""
    z, _ = _bumps(seed=3)
    sigma, k = 2.0, 4.0  # the largest of ~10^4 correlated errors is about 3 sigma
    core = orokit.topology.engine.orometry(z, min_prominence_m=20)
    lo, hi = prominence_bounds(core.prominence, core.key_saddle_cell < 0, sigma, k)
    kw = dict(sigma_m=sigma, corr_cells=(4.0, 4.0), radius_cells=(4.0, 4.0), samples=12, min_prominence_m=20)
    a = monte_carlo(z, core.peak_row, core.peak_col, rng=np.random.default_rng(5), **kw)
    b = monte_carlo(z, core.peak_row, core.peak_col, rng=np.random.default_rng(5), **kw)
    np.testing.assert_array_equal(a.prominence_samples, b.prominence_samples)
    inside = a.max_abs_error_m <= k * sigma
    assert inside.sum() >= 6, "most realisations stay within 4 sigma"
    s = a.prominence_samples[inside]
    assert np.isfinite(s).all(), "every hill survives an error below its prominence"
    assert ((s >= lo - 1e-9) & (s <= hi + 1e-9)).all()
    # the samples really vary (a test that could not fail otherwise)
    assert np.ptp(s, axis=0).max() > 0.5
    assert (a.p_exists == 1).all()
    np.testing.assert_allclose(a.prominence_median, np.median(a.prominence_samples, axis=0))


def test_small_hill_disappears_in_noise():
    """A bump of < 3 m prominence on a slope under 5 m error: p_exists well below 1 at a 1 m threshold."""
    yy, xx = np.mgrid[0:60, 0:60].astype(float)
    z = 0.2 * yy + 3.0 * np.exp(-((yy - 30) ** 2 + (xx - 30) ** 2) / 8.0) + 0.02 * xx
    core = orokit.topology.engine.orometry(z, min_prominence_m=1.0)
    j = np.flatnonzero((abs(core.peak_row - 30) <= 1) & (abs(core.peak_col - 30) <= 1))
    assert j.size == 1 and 1.0 <= core.prominence[j[0]] <= 3.0
    mc = monte_carlo(z, core.peak_row[j], core.peak_col[j], sigma_m=5.0, corr_cells=(6.0, 6.0),
                     radius_cells=(2.0, 2.0), samples=20, rng=np.random.default_rng(0), min_prominence_m=1.0)
    assert mc.p_exists[0] < 0.9


def test_correlated_noise_std_and_correlation_length():
    rng = np.random.default_rng(11)
    e = correlated_noise((400, 400), 3.0, (10.0, 10.0), rng)
    assert e.std() == pytest.approx(3.0)
    c = np.mean(e[:, :-10] * e[:, 10:]) / e.var()  # covariance exp(-1) at one correlation length
    assert c == pytest.approx(np.exp(-1), abs=0.08)
    w = correlated_noise((300, 300), 1.0, (0.0, 0.0), rng)
    assert abs(np.mean(w[:, :-1] * w[:, 1:])) < 0.05  # white
    assert not correlated_noise((5, 5), 0.0, (3.0, 3.0), rng).any()


def test_cli_dem_error(make_dem, tmp_path):
    import rasterio
    from rasterio.transform import from_origin

    from orokit.cli.main import cli

    z, _ = _bumps()
    p = tmp_path / "dem.tif"
    with rasterio.open(p, "w", driver="GTiff", width=z.shape[1], height=z.shape[0], count=1, dtype="float32",
                       crs="EPSG:32633", transform=from_origin(500000, 4000000, 30, 30)) as ds:
        ds.write(z.astype("float32"), 1)
    out = tmp_path / "out"
    res = CliRunner().invoke(cli, ["-q", "analyze", str(p), "-o", str(out), "--min-prominence", "20m",
                                   "--dem-error", "2m", "--error-corr", "120m", "--samples", "4", "--seed", "3",
                                   "--no-progress", "--no-isolation"])
    assert res.exit_code == 0, res.output
    t = pd.read_csv(out / "peaks.csv")
    np.testing.assert_allclose(t["prominence_high"] - t["prominence"],
                               np.where(t["saddle_row"] < 0, 4.0, 8.0), atol=1e-4)
    assert t["p_exists"].between(0, 1).all() and t["prominence_median"].notna().all()
    meta = json.loads((out / "analysis.json").read_text())
    assert meta["attrs"]["seed"] == 3 if "attrs" in meta else meta["seed"] == 3
    bad = CliRunner().invoke(cli, ["analyze", str(p), "-o", str(tmp_path / "o2"), "--samples", "3"])
    assert bad.exit_code == 2 and "--dem-error" in bad.output


def test_match_prefers_the_prominence_closest_to_the_peaks_own():
    """A more prominent neighbour nearer than the peak's own survivor is not taken for it."""
    from orokit.topology.uncertainty import _match

    pts = np.array([[0.0, 0.0], [5.0, 5.0]])
    q_row, q_col = np.array([0.3, 0.0, 5.0]), np.array([0.0, 0.5, 5.0])
    q_prom = np.array([100.0, 12.0, 40.0])
    with_target = _match(pts, q_row, q_col, q_prom, np.array([10.0, 41.0]))
    np.testing.assert_array_equal(with_target, [12.0, 40.0])
    nearest = _match(pts, q_row, q_col, q_prom, None)
    np.testing.assert_array_equal(nearest, [100.0, 40.0])
    far = _match(np.array([[20.0, 20.0]]), q_row, q_col, q_prom, np.array([10.0]))
    assert np.isnan(far[0])


def test_monte_carlo_does_not_depend_on_the_number_of_threads():
    z, _ = _bumps(seed=4)
    core = orokit.topology.engine.orometry(z, min_prominence_m=20)
    kw = dict(sigma_m=2.0, corr_cells=(4.0, 4.0), radius_cells=(4.0, 4.0), samples=6, min_prominence_m=20,
              peak_prominence=core.prominence)
    one = monte_carlo(z, core.peak_row, core.peak_col, rng=np.random.default_rng(9), workers=1, **kw)
    two = monte_carlo(z, core.peak_row, core.peak_col, rng=np.random.default_rng(9), workers=2, **kw)
    np.testing.assert_array_equal(one.prominence_samples, two.prominence_samples)
    np.testing.assert_array_equal(one.max_abs_error_m, two.max_abs_error_m)
    assert np.ptp(one.prominence_samples, axis=0).max() > 0.1
