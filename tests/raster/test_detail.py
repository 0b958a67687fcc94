"""Sub-lambda detail of the renderer: power-law fit and continuation (orokit.raster.noise), facet smoothing."""
from __future__ import annotations

import numpy as np
import pytest

import orokit
from orokit.raster.noise import lowpass, power_law_fit, power_law_noise, spectral_noise
from orokit.raster.params import RenderParams
from orokit.raster.render import render_elevation
from orokit.validate.landform import band_power

from helpers.trees import assert_keeps_small_tree, small_tree


@pytest.mark.parametrize("beta", [2.0, 3.0, 4.0])
def test_power_law_fit_recovers_the_spectral_slope_of_power_law_noise(beta):
    z = spectral_noise((512, 512), 100.0, rms=50.0, beta=beta, largest_m=1e6, rng=3)
    c, b = power_law_fit(z, 100.0, fit_m=(1000.0, 10_000.0))
    assert abs(b - beta) < 0.25  # the taper leaks a little low-wavenumber power upwards
    assert c > 0


def test_power_law_noise_has_the_fitted_density_at_any_cell_size():
    """Noise made from (c, beta) and fitted again gives the same density at 50 and 100 m cells
    (the amplitude is in metres, not relative to the grid)."""
    c0, b0 = 1.0e-3, 3.0
    for res, n in ((100.0, 512), (50.0, 1024)):
        z = power_law_noise((n, n), res, c=c0, beta=b0, largest_m=1e6, rng=1)
        c, b = power_law_fit(z, res, fit_m=(1000.0, 10_000.0))
        assert abs(b - b0) < 0.2
        # density at 2 km wavelength within a factor 1.5
        k = 1.0 / 2000.0
        assert 1 / 1.5 < (c * k ** -b) / (c0 * k ** -b0) < 1.5


def test_power_law_noise_is_zero_above_its_largest_wavelength():
    bands = ((100.0, 400.0), (5000.0, 20_000.0))
    hp, full = (band_power(power_law_noise((512, 512), 50.0, c=1.0e-3, beta=3.0, largest_m=m, rng=2), (50.0, 50.0),
                           bands_m=bands) for m in (500.0, 1e6))
    assert hp[0] > 0.5 * full[0]  # short wavelengths kept
    assert hp[1] < 1e-3 * full[1]  # long ones removed
    assert power_law_noise((8, 8), 50.0, c=0.0, beta=3.0).any() == False  # noqa: E712


def test_power_law_fit_needs_a_grid_larger_than_the_band():
    assert power_law_fit(np.zeros((16, 16)), 100.0, fit_m=(1000.0, 10_000.0)) == (0.0, 3.0)


def test_deficit_noise_adds_nothing_where_the_surface_has_the_power_law_already():
    """``minus`` = a surface with (at least) the target density: the deficit is ~0; a flat surface: the full law."""
    c0, b0 = 1.0e-3, 3.0
    kw = {"c": c0, "beta": b0, "largest_m": 2000.0}
    full = power_law_noise((256, 256), 50.0, **kw, rng=4)
    rich = power_law_noise((256, 256), 50.0, c=4 * c0, beta=b0, largest_m=1e6, rng=5)
    none = power_law_noise((256, 256), 50.0, **kw, minus=np.zeros((256, 256)), rng=4)
    np.testing.assert_allclose(none, full, rtol=1e-4, atol=1e-4)
    left = power_law_noise((256, 256), 50.0, **kw, minus=rich, rng=4)
    assert float(left.std()) < 0.05 * float(full.std())


def _render(params, seed=7):
    return render_elevation(small_tree(), cell_size_m=50.0, erosion=False, params=params, rng=seed)


@pytest.mark.parametrize("params", [
    RenderParams(smooth_m=100.0, detail_gain=1.0, detail_replace=False, detail_fit_m=(400.0, 2000.0),
                 detail_largest_m=1000.0, detail_steepen=0.0),
    RenderParams(detail_gain=1.0),
], ids=["smooth+deficit", "replace"])
def test_render_with_detail_keeps_the_tree_orometry_and_is_deterministic(params):
    a, b = _render(params), _render(params)
    np.testing.assert_array_equal(a.values, b.values)
    plain = _render(RenderParams(detail_gain=0.0))
    assert not np.array_equal(a.values, plain.values)
    assert_keeps_small_tree(a)


def test_steepened_noise_keeps_long_and_loses_short_wavelengths_as_k_to_the_minus_steepen():
    kw = {"c": 1.0e-3, "beta": 3.0, "largest_m": 1e6, "rng": 6}
    plain = power_law_noise((512, 512), 25.0, **kw)
    steep = power_law_noise((512, 512), 25.0, **kw, steepen=1.0, steepen_below_m=400.0)
    bands = ((50.0, 70.0), (900.0, 1500.0))
    ps, pp = band_power(steep, (25.0, 25.0), bands_m=bands), band_power(plain, (25.0, 25.0), bands_m=bands)
    np.testing.assert_allclose(ps[1] / pp[1], 1.0, rtol=0.02)  # above 400 m: the same law
    assert 60.0 / 400.0 * 0.8 < ps[0] / pp[0] < 60.0 / 400.0 * 1.25  # (k 400 m)^-1 at ~60 m


def test_lowpass_and_sharp_noise_split_the_spectrum_at_the_same_wavelength():
    """What :func:`lowpass` removes below L, ``power_law_noise(sharp=True)`` makes: the two are complements."""
    z = spectral_noise((256, 256), 25.0, rms=10.0, beta=3.0, largest_m=1e6, rng=8)
    bands = ((50.0, 150.0), (400.0, 1000.0))
    low = band_power(lowpass(z, 25.0, 200.0), (25.0, 25.0), bands_m=bands)
    full = band_power(z, (25.0, 25.0), bands_m=bands)
    assert low[0] < 1e-3 * full[0] and abs(low[1] / full[1] - 1.0) < 0.05
    d = band_power(power_law_noise((256, 256), 25.0, c=1e-3, beta=3.0, largest_m=200.0, sharp=True, rng=9),
                   (25.0, 25.0), bands_m=((50.0, 150.0), (800.0, 2000.0)))
    assert d[1] < 1e-2 * d[0]  # k^-3 is 100-1000 x larger there: the high-pass removes it


def test_min_beta_bounds_the_continuation_of_a_shallow_spectrum():
    """A dune field's shallow law (beta ~1) continued below 1 km would make metres of detail at 100 m;
    ``min_beta`` 4 steepens it there, long wavelengths untouched."""
    kw = {"c": 1.0, "beta": 1.0, "largest_m": 1e6, "steepen_below_m": 1000.0, "rng": 10}
    bands = ((50.0, 150.0), (2000.0, 5000.0))
    free = band_power(power_law_noise((512, 512), 25.0, **kw), (25.0, 25.0), bands_m=bands)
    bound = band_power(power_law_noise((512, 512), 25.0, **kw, min_beta=4.0), (25.0, 25.0), bands_m=bands)
    np.testing.assert_allclose(bound[1] / free[1], 1.0, rtol=0.02)
    # at ~100 m the extra k^-3 below 1 km: (1000 / 100)^3 = 1000 x less power (band average: 300-3000)
    assert 300.0 < free[0] / bound[0] < 3000.0


def test_detail_weights_are_zero_on_flats_one_on_slopes_and_linear_between():
    from orokit.raster.render import _detail_weights

    xx = np.mgrid[0:40, 0:40][1] * 30.0
    near = np.zeros(xx.shape, np.float32)
    for deg, want in ((1.0, 0.0), (3.0, 0.5), (5.0, 1.0)):
        act, weight = _detail_weights(np.tan(np.radians(deg)) * xx, 30.0, near, 200.0, 1.0, 2.0)
        np.testing.assert_allclose(act[5:-5, 5:-5], want, atol=0.01)
        np.testing.assert_allclose(weight[5:-5, 5:-5], want, atol=0.01)  # a plane: slope weight 1 (RMS 1)
    act, _ = _detail_weights(np.tan(np.radians(1.0)) * xx, 30.0, near, 200.0, 1.0, 0.0)
    assert (act == 1.0).all()  # flat_deg 0: the detail acts everywhere
    near[:, :20] = 1.0  # next to a peak: no detail
    act, weight = _detail_weights(np.tan(np.radians(5.0)) * xx, 30.0, near, 200.0, 1.0, 2.0)
    assert (act[:, :20] == 0).all() and (weight[:, :20] == 0).all() and (act[5:-5, 25:-5] > 0.99).all()
    # a flat floor beside a slope: the floor and its edge cell stay 0, the slope two cells away gets detail
    z = np.maximum(xx - 600.0, 0.0) * np.tan(np.radians(10.0))
    act, _ = _detail_weights(z, 30.0, np.zeros(z.shape, np.float32), 200.0, 1.0, 2.0)
    assert (act[:, :21] == 0).all() and (act[5:-5, 23:-5] == 1.0).all()
    # the slope weight follows the slope: twice as steep, twice the weight
    z = np.where(xx < 600.0, 0.1 * xx, 60.0 + 0.2 * (xx - 600.0))
    _, weight = _detail_weights(z, 30.0, np.zeros(z.shape, np.float32), 200.0, 1.0, 0.0)
    np.testing.assert_allclose(weight[20, 30] / weight[20, 5], 2.0, rtol=0.02)


def test_detail_leaves_the_flats_of_the_skeleton_flat():
    """With ``detail_flat_deg`` the detail does not touch the cells whose skeleton is flatter than that:
    a render of the same tree keeps at least as many cells below 2 deg as the render without detail's
    flats it started from, and more than the detail applied everywhere."""
    kw = {"detail_gain": 1.0, "noise_ratio": 0.0}

    def flat_share(p):
        z = _render(p).values
        gy, gx = np.gradient(z, 50.0)
        return float((np.degrees(np.arctan(np.hypot(gx, gy))) < 2.0).mean())

    everywhere, kept = flat_share(RenderParams(**kw, detail_flat_deg=0.0)), flat_share(RenderParams(**kw, detail_flat_deg=2.0))
    assert kept > everywhere


@pytest.mark.parametrize("gain", [1.0, 100.0])
def test_detail_never_makes_a_peak_of_the_tree_prominence(gain):
    """Metamorphic: however strong the sub-lambda detail (at gain 100 it has more than 30 m RMS, more than eps,
    and makes dozens of hills), with sub-eps hills kept, the render's peaks of prominence >= eps are
    exactly the tree's, with the tree's prominences."""
    p = RenderParams(detail_gain=gain, detail_flat_deg=2.0, keep_hill_ratio=0.5, cut_slope=0.05)
    z = _render(p, seed=11)
    assert_keeps_small_tree(z)
    if gain > 30.0:
        import json

        assert json.loads(z.attrs["parameters"])["detail_rms_m"] > 30.0
        assert len(orokit.analyze(z, min_prominence_m=1.0, isolation=False).peaks) > 50


def test_detail_weights_do_not_follow_the_slope_at_power_zero():
    """``detail_slope_power`` 0 (the default since session 16): the detail is as strong on a gentle slope as on a
    steep one (real DEMs' sub-200 m curvature hardly depends on the slope; the slope-weighted detail put the
    render's curvature extremes on its steepest cells and left its gentle slopes too smooth)."""
    from orokit.raster.render import _detail_weights

    xx = np.mgrid[0:40, 0:60][1] * 30.0
    z = np.where(xx < 900.0, np.tan(np.radians(5.0)) * xx,
                 np.tan(np.radians(5.0)) * 900.0 + np.tan(np.radians(35.0)) * (xx - 900.0))
    near = np.zeros(z.shape, np.float32)
    gentle, steep = (slice(5, -5), slice(5, 20)), (slice(5, -5), slice(40, -5))
    _, w0 = _detail_weights(z, 30.0, near, 200.0, 0.0, 2.0)
    np.testing.assert_allclose(w0[gentle], 1.0)
    np.testing.assert_allclose(w0[steep], 1.0)
    _, w1 = _detail_weights(z, 30.0, near, 200.0, 1.0, 2.0)
    ratio = float(w1[steep].mean() / w1[gentle].mean())
    np.testing.assert_allclose(ratio, np.tan(np.radians(35.0)) / np.tan(np.radians(5.0)), rtol=0.02)
    assert RenderParams().detail_slope_power == 0.0
