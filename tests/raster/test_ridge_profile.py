"""Crests that fall from their peak at a bounded slope (``RenderParams.ridge_max_slope``, an option, off)."""
from __future__ import annotations

import numpy as np
import pytest

import orokit
from orokit.errors import InputError
from orokit.raster.params import RenderParams
from orokit.raster.render import render_elevation
from orokit.raster.skeleton import RIDGE_TAIL_SLOPE, build_skeleton, steep_ridge_profile
from orokit.validate.roundtrip import compare_peaks

from helpers.trees import small_tree


def test_steep_ridge_profile_falls_at_the_slope_then_runs_low_never_above_the_line():
    rng = np.random.default_rng(0)
    m = 200
    peak = np.column_stack([np.zeros(m), np.zeros(m), rng.uniform(500.0, 3000.0, m)])
    length = rng.uniform(200.0, 20000.0, m)
    saddle = np.column_stack([length, np.zeros(m), peak[:, 2] - rng.uniform(0.0, 2500.0, m)])
    saddle[:, 2] = np.minimum(saddle[:, 2], peak[:, 2])
    f = steep_ridge_profile(peak, saddle, 0.8)
    t = np.linspace(0.0, 1.0, 101)
    for i in range(m):
        w = f(t, np.full(t.size, i))
        h = peak[i, 2] - saddle[i, 2]
        assert w[0] == 0.0 and w[-1] == pytest.approx(1.0)
        assert (np.diff(w) >= -1e-12).all()  # the crest never climbs toward the saddle
        assert (w >= t - 1e-12).all()  # never above the straight line
        z = peak[i, 2] - w * h
        d = t * length[i]
        if h / length[i] >= 0.8:  # a short or steep piece keeps its line
            np.testing.assert_allclose(w, t, atol=1e-12)
        else:  # above its tail the crest falls at 0.8 from the peak; below it, at the tail's slope to the saddle
            tail = min(RIDGE_TAIL_SLOPE, h / length[i]) * (length[i] - d)
            np.testing.assert_allclose(z - saddle[i, 2], np.maximum(peak[i, 2] - 0.8 * d - saddle[i, 2], tail),
                                       atol=1e-6)
    with pytest.raises(ValueError, match="max_slope"):
        steep_ridge_profile(peak, saddle, 0.0)
    with pytest.raises(InputError, match="ridge_max_slope"):
        RenderParams(ridge_max_slope=-1.0)


def test_steep_ridges_lie_at_or_below_the_straight_crests_and_keep_the_tree_orometry():
    """The same jitter draws: every refined ridge point lies where the straight crest put it in the plane and no
    higher, lower on the small tree's long gentle pieces; a render keeps the tree's peaks and prominences."""
    kw = {"extent": (0.0, 0.0, 8000.0, 8000.0), "rng": 3}
    plain = build_skeleton(small_tree(), params=RenderParams(lam=200.0), **kw)
    steep = build_skeleton(small_tree(), params=RenderParams(lam=200.0, ridge_max_slope=0.8), **kw)
    np.testing.assert_array_equal(plain.ridges.xy, steep.ridges.xy)
    assert (steep.ridges.z <= plain.ridges.z + 1e-9).all()
    assert (steep.ridges.z < plain.ridges.z - 100.0).any()
    z = render_elevation(small_tree(), cell_size_m=50.0, erosion=False, params=RenderParams(ridge_max_slope=0.8),
                         rng=7)
    res = orokit.analyze(z, min_prominence_m=30.0, isolation=False)
    comp = compare_peaks(small_tree(), res.peaks, min_prominence_m=30.0, distance_tol_m=100.0)
    assert comp.recovered_share == 1.0 and len(comp.extra) == 0
    np.testing.assert_allclose(comp.peaks["raster_prominence"].to_numpy(), [1500.0, 200.0, 200.0, 150.0, 100.0],
                               atol=6.0)


def test_plateau_pieces_tell_a_level_base_from_a_falling_one():
    """Saddles all at one level under high peaks (volcanoes on a plain): every piece is a plateau's; the same
    field tilted so the base level falls 1 km over the domain (a range draining to its main valleys): none."""
    from orokit.raster.skeleton import plateau_pieces

    rng = np.random.default_rng(1)
    sxy = rng.uniform(0.0, 50000.0, (300, 2))
    pxy = rng.uniform(0.0, 50000.0, (300, 2))
    peaks = np.column_stack([pxy, 4000.0 + rng.uniform(200.0, 1500.0, 300)])
    level = np.column_stack([sxy, 4000.0 + rng.uniform(0.0, 20.0, 300)])
    assert plateau_pieces(level, peaks, level, 0.05).all()
    tilt = level.copy()
    tilt[:, 2] -= 2.0 * sxy[:, 0] / 50.0  # 2 km over 50 km, saddles and peaks alike
    peaks_t = peaks.copy()
    peaks_t[:, 2] -= 2.0 * pxy[:, 0] / 50.0
    assert plateau_pieces(tilt, peaks_t, tilt, 0.05).mean() < 0.2


def test_ridge_plateau_drop_is_checked():
    """A negative or NaN drop selected no piece, and a drop without ridge_max_slope did nothing (both silently):
    refused, naming the fix."""
    for bad in (-0.1, 0.0, float("nan")):
        with pytest.raises(InputError, match="ridge_plateau_drop must be > 0"):
            RenderParams(ridge_max_slope=0.8, ridge_plateau_drop=bad)
    with pytest.raises(InputError, match="set ridge_max_slope too"):
        RenderParams(ridge_plateau_drop=0.05)
    assert RenderParams(ridge_max_slope=0.8, ridge_plateau_drop=0.05).ridge_plateau_drop == 0.05
