"""The distance-transform surface between ridges and rivers (RenderParams.surface = "field")."""
from __future__ import annotations

import numpy as np
import pytest

import orokit
from orokit.raster.interpolate import field_elevation
from orokit.raster.params import RenderParams
from orokit.raster.render import render_elevation

from helpers.trees import assert_keeps_small_tree, small_tree


def _line(rows, col):
    rows = np.asarray(rows)
    return rows, np.full(rows.size, col)


def test_field_between_a_straight_ridge_and_river_is_a_plane_of_known_slope():
    # ridge at column 0 (1000 m), river at column 40 (200 m), 25 m cells: slope 800 / 1000 m
    n, res = 30, 25.0
    h = field_elevation((n, 41), res, _line(range(n), 0), np.full(n, 1000.0), _line(range(n), 40),
                        np.full(n, 200.0), np.zeros(n))
    gx = np.diff(h, axis=1) / res
    np.testing.assert_allclose(gx, -0.8, atol=1e-4)
    np.testing.assert_allclose(h[:, 20], 600.0, atol=1e-3)


def test_valley_floor_is_flat_within_its_width_and_profile_bends_the_flank():
    n, res = 10, 25.0
    args = ((n, 41), res, _line(range(n), 0), np.full(n, 1000.0), _line(range(n), 40), np.full(n, 200.0))
    h = field_elevation(*args, np.full(n, 100.0))
    np.testing.assert_allclose(h[:, 36:], 200.0)  # within 100 m of the river
    assert (h[:, 35] > 200.0).all()
    concave = field_elevation(*args, np.zeros(n), profile=lambda u: u * u)
    lin = field_elevation(*args, np.zeros(n))
    assert (concave[:, 1:40] < lin[:, 1:40]).all()  # below the straight line: a concave valley side
    np.testing.assert_allclose(concave[:, [0, 40]], lin[:, [0, 40]])


def test_field_has_no_summit_off_the_ridges_and_no_step():
    """Ridges of varying height between winding rivers: every local maximum is a ridge cell, and
    no step between neighbours exceeds the steepest ridge-to-river gradient."""
    res, ny, nx = 30.0, 120, 160
    rng = np.random.default_rng(3)
    rows = np.arange(ny)
    ridges, rz, rivers, vz = [], [], [], []
    for k, c in enumerate((30, 80, 130)):
        col = (c + 6 * np.sin(rows / 15.0 + k)).astype(int)
        ridges.append((rows, col))
        rz.append(1500.0 + 600.0 * np.sin(np.pi * rows / ny) * rng.uniform(0.5, 1.0))
    for k, c in enumerate((5, 55, 105, 155)):
        col = (c + 4 * np.cos(rows / 11.0 + k)).astype(int)
        rivers.append((rows, col))
        vz.append(400.0 + 2.0 * rows)  # beds descend northwards (row 0)
    rr = (np.concatenate([r for r, _ in ridges]), np.concatenate([c for _, c in ridges]))
    vv = (np.concatenate([r for r, _ in rivers]), np.concatenate([c for _, c in rivers]))
    h = field_elevation((ny, nx), res, rr, np.concatenate(rz), vv, np.concatenate(vz), np.full(vv[0].size, 40.0))
    is_ridge = np.zeros((ny, nx), bool)
    is_ridge[rr] = True
    from scipy import ndimage

    ring = np.ones((3, 3), bool)
    ring[1, 1] = False
    local_max = h > ndimage.maximum_filter(h, footprint=ring, mode="constant", cval=-np.inf)  # strict summits
    assert local_max[is_ridge].any()
    assert not (local_max & ~is_ridge).any()
    # the largest ridge-river drop over the narrowest gap (> 0 cells) bounds every step
    steepest = (np.concatenate(rz).max() - np.concatenate(vz).min()) / (2 * res)
    assert np.abs(np.diff(h, axis=1)).max() <= steepest * res
    assert np.abs(np.diff(h, axis=0)).max() <= steepest * res


def test_field_needs_ridges_and_rivers():
    with pytest.raises(ValueError, match="ridge cell and one river cell"):
        field_elevation((5, 5), 10.0, (np.array([0]), np.array([0])), np.array([1.0]),
                        (np.array([], int), np.array([], int)), np.array([]), np.array([]))


@pytest.mark.parametrize("weight", [1.0, 0.5])
def test_field_render_keeps_the_tree_orometry(weight):
    tree = small_tree()
    dem = render_elevation(tree, cell_size_m=50.0, erosion=False,
                           params=RenderParams(surface="field", field_weight=weight), rng=7)
    assert_keeps_small_tree(dem)
    with pytest.raises(orokit.errors.InputError, match="surface"):
        RenderParams(surface="mesh")


def test_ground_beyond_the_last_river_falls_gently_to_a_bounded_depth():
    # ridge at column 0, river at column 20, border beyond it: no ridge on the far side
    n, res = 5, 50.0
    h = field_elevation((n, 41), res, _line(range(n), 0), np.full(n, 900.0), _line(range(n), 20),
                        np.full(n, 100.0), np.zeros(n), beyond_slope=0.05, beyond_depth_m=30.0)
    np.testing.assert_allclose(h[:, 21:26], np.tile(100.0 - 0.05 * res * np.arange(1, 6), (n, 1)), atol=1e-3)
    np.testing.assert_allclose(h[:, 32:], 70.0, atol=1e-3)
    assert (np.diff(h[:, 20:], axis=1) <= 1e-4).all()  # never rises towards the border
