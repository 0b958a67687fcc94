"""Orometry enforcement of the renderer: tree bottlenecks, basin capping, saddles near peaks."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import rioxarray  # noqa: F401
import xarray as xr
from affine import Affine

import orokit
from orokit.raster import _kernels
from orokit.raster.rasterize import Grid
from orokit.raster.enforce import cap_basins
from orokit.raster.render import render_elevation
from orokit.raster.skeleton import separate_saddles
from orokit.topology.divide_tree import DivideTree
from orokit.validate.roundtrip import compare_peaks


def as_dem(z: np.ndarray, res: float = 1.0) -> xr.DataArray:
    ny, nx = z.shape
    da = xr.DataArray(z.astype(np.float32), dims=("y", "x"), attrs={"units": "m"},
                      coords={"y": 1000.0 - res * (np.arange(ny) + 0.5), "x": res * (np.arange(nx) + 0.5)})
    return da.rio.write_crs("EPSG:32633").rio.write_transform(Affine(res, 0.0, 0.0, 0.0, -res, 1000.0))


def test_bottlenecks_of_a_hand_made_tree():
    # chain 0 -(100)- 1 -(80)- 2 -(90)- 3, and a lone peak 4
    ea, eb, ez = np.array([0, 1, 2]), np.array([1, 2, 3]), np.array([100.0, 80.0, 90.0])
    parent, height, depth = _kernels.merge_tree(5, ea, eb, ez)
    a = np.array([0, 0, 2, 1, 3, 0])
    b = np.array([1, 3, 3, 2, 0, 4])
    got = _kernels.bottlenecks(parent, height, depth, a, b)
    np.testing.assert_array_equal(got, [100.0, 80.0, 90.0, 80.0, 80.0, -np.inf])


def test_cap_basins_closes_a_bypass_above_the_saddle():
    """Peaks A 100 m and B 90 m joined by a ridge through a 50 m saddle, plus a 70 m bypass."""
    z = np.zeros((9, 11), np.float32)
    z[5, 2:9] = [100, 83, 66, 50, 63, 76, 90]  # the ridge A - saddle - B (row 5)
    z[3, 2:9] = 70.0  # a shelf higher than the saddle joining both flanks
    z[4, 2], z[4, 8] = 85.0, 80.0
    before = orokit.analyze(as_dem(z), min_prominence_m=0.0, isolation=False).peaks
    assert before.loc[(before["row"] == 5) & (before["col"] == 8), "prominence"].item() == pytest.approx(20.0)
    grid = Grid(0.0, 1000.0, 1.0, 9, 11)
    centre = lambda r, c: [c + 0.5, 1000.0 - r - 0.5]  # noqa: E731
    skel = SimpleNamespace(n_peaks=2, node_xyz=np.array([centre(5, 2) + [100.0], centre(5, 8) + [90.0],
                                                         centre(5, 5) + [50.0]]),
                           edges=np.array([[0, 1, 0]]))
    floor = np.full(z.shape, -np.inf, np.float32)
    floor[5, 2:9] = 50.0  # ridge cells may go down to their saddle
    floor[5, 2] = floor[5, 8] = floor[5, 5] = np.inf
    stats = cap_basins(z, grid, skel, floor=floor, drop_m=0.5)
    assert stats["left"] == 0 and stats["capped"] > 0
    after = orokit.analyze(as_dem(z), min_prominence_m=0.0, isolation=False).peaks
    b = after[(after["row"] == 5) & (after["col"] == 8)]
    assert b["prominence"].item() == pytest.approx(40.0)  # 90 - 50: the tree's saddle is the key saddle again
    assert (z[5, [2, 5, 8]] == [100, 50, 90]).all()  # peaks and saddle untouched
    assert len(after[after["prominence"] > 0]) == 2  # no other hill


def test_separate_saddles_moves_only_close_saddles():
    p = np.array([[0.0, 0.0, 500.0], [1000.0, 0.0, 400.0], [0.0, 100.0, 450.0]])
    s = np.array([[10.0, 5.0, 300.0], [0.0, 50.0, 420.0]])
    e = np.array([[0, 1, 0], [0, 2, 1]])
    out = separate_saddles(p, s, e, 150.0)
    # saddle 0 slides to 150 m from peak 0 along the ridge; elevations never change
    assert np.hypot(*out[0, :2]) >= 150.0 - 1e-9 and abs(out[0, 1]) <= 5.0
    # saddle 1: the ridge (100 m) is shorter than twice the clearance -> the middle
    np.testing.assert_allclose(out[1, :2], [0.0, 50.0])
    np.testing.assert_array_equal(out[:, 2], s[:, 2])
    np.testing.assert_array_equal(separate_saddles(p, s, e, 0.0), s)


def test_saddle_in_the_cell_of_its_peak_keeps_the_peak():
    """A key saddle 58 m from its peak (same 100 m cell) must not overwrite the peak."""
    tree = DivideTree.from_arrays([[2000.0, 2000.0, 900.0], [4060.0, 2050.0, 700.0]],
                                  [[4010.0, 2020.0, 600.0]], [[0, 1, 0]], attrs={"extent": [0, 0, 6000, 4000]})
    dem = render_elevation(tree, cell_size_m=100.0, erosion=False, rng=0)
    res = orokit.analyze(dem, min_prominence_m=30.0, isolation=False)
    comp = compare_peaks(tree, res.peaks, min_prominence_m=30.0, distance_tol_m=200.0)
    assert comp.recovered_share == 1.0
    assert comp.peaks["raster_prominence"].to_numpy() == pytest.approx([900.0, 100.0], abs=5.0)


def _cone(ny: int, nx: int, top: float, r0: float, c0: float, slope: float) -> np.ndarray:
    y, x = np.mgrid[0:ny, 0:nx]
    return (top - slope * np.hypot(y - r0, x - c0)).astype(np.float32)


def test_flood_levels_give_the_pass_and_the_peak_it_comes_from():
    # a tree peak (owner 0) on the left, a spurious knob on the right joined by a col at 45 m
    z = np.maximum(_cone(9, 15, 100.0, 4, 2, 10.0), _cone(9, 15, 75.0, 4, 11, 10.0))
    own = np.where(np.arange(15)[None, :] < 7, 0, -1) * np.ones((9, 1), np.int64)
    level, source = _kernels.flood_levels(z, own == -1, own)
    assert z[4, 8] == 45.0 and level[4, 11] == pytest.approx(45.0)  # the knob's pass to owner 0
    assert (source[own == -1] == 0).all() and (source[own == 0] == -1).all()
    assert np.isneginf(level[own == 0]).all()


def test_cut_hills_fall_from_their_pass_and_keep_an_ascending_path():
    """The graded cut makes a bowl below the pass (no flat shelf) and leaves no maximum inside."""
    left, right = _cone(21, 31, 100.0, 10, 3, 4.0), _cone(21, 31, 90.0, 10, 20, 4.0)
    z = np.maximum(left, right)
    mask = right > left  # the spurious hill's side
    flat, graded = z.copy(), z.copy()
    _kernels.reconstruct_masked(flat, mask, 1e-3)
    _kernels.reconstruct_masked(graded, mask, 1e-3, 2.0, 10.0)
    pass_z = float(flat[10, 20]) + 1e-2
    assert float(z[10, 20]) > pass_z + 10.0
    cut = mask & (z > pass_z)
    assert np.ptp(flat[cut]) < 0.1  # the old cut: a shelf at the pass
    assert graded[cut].max() <= pass_z and graded[cut].min() >= pass_z - 10.0 - 0.1
    assert np.ptp(graded[cut]) > 10.0 - 2.0 - 0.1  # a bowl down to within one grade step of max_depth
    assert (graded <= z + 1e-6).all() and (graded[~mask] == z[~mask]).all()
    from orokit.topology.engine import steepest_ascent_basins
    for out in (flat, graded):
        _, tops = steepest_ascent_basins(out)
        assert not mask.reshape(-1)[tops].any()  # every cut cell ascends out of the mask


def test_cap_basins_keeps_low_hills_and_cuts_high_ones():
    """A knob of prominence < keep_hills_m beside a tree peak stays; one above it is cut."""
    z = np.maximum(_cone(15, 41, 200.0, 7, 5, 5.0), _cone(15, 41, 190.0, 7, 35, 5.0))
    z = np.maximum(z, _cone(15, 41, z[7, 12] + 25.0, 7, 12, 8.0))  # low knob on A's flank
    z = np.maximum(z, _cone(15, 41, z[7, 28] + 40.0, 7, 28, 8.0))  # knob higher than B
    before = z.copy()
    prom = orokit.analyze(as_dem(z), min_prominence_m=1.0, isolation=False).peaks.set_index(["row", "col"])
    assert prom.loc[(7, 12), "prominence"] < 27.0 and prom.loc[(7, 28), "prominence"] > 30.0
    grid = Grid(0.0, 1000.0, 1.0, 15, 41)
    centre = lambda r, c: [c + 0.5, 1000.0 - r - 0.5]  # noqa: E731
    skel = SimpleNamespace(n_peaks=2, node_xyz=np.array([centre(7, 5) + [200.0], centre(7, 35) + [190.0],
                                                         centre(7, 21) + [120.0]]),
                           edges=np.array([[0, 1, 0]]))
    floor = np.full(z.shape, -np.inf, np.float32)
    floor[7, [5, 21, 35]] = np.inf
    stats = cap_basins(z, grid, skel, floor=floor, keep_hills_m=27.0, cut_slope=0.5, cut_depth_m=27.0)
    assert stats["kept"] >= 1 and stats["cut"] > 0 and stats["left"] == 0
    assert (z[5:10, 10:15] == before[5:10, 10:15]).all()  # the low knob is untouched
    assert z[7, 28] < 190.0  # the high knob is cut below B
    after = orokit.analyze(as_dem(z), min_prominence_m=1.0, isolation=False).peaks.set_index(["row", "col"])
    big = after[after["prominence"] >= 27.0]
    assert sorted(big.index) == [(7, 5), (7, 35)]
    assert after.loc[(7, 35), "prominence"] == pytest.approx(70.0, abs=0.6)  # 190 - the tree's saddle
    assert (7, 12) in after.index  # the knob is still there, below eps


def test_descending_trench_is_bounded():
    z = np.full((11, 31), 100.0, np.float32)
    label = np.full(z.shape, -1, np.int32)
    args = (z, 0.0, 11.0, 1.0, np.array([15.5]), np.array([5.5]), np.array([90.0]), np.array([0.0]),
            np.array([1.0]), 4.0, 0.5, label)
    level, descending = z.copy(), z.copy()
    _kernels.carve_saddles(level, *args[1:])
    _kernels.carve_saddles(descending, *args[1:], 2.0, 3.0)
    col = descending[:, 15]
    assert (level[:, 15][level[:, 15] < 100] == pytest.approx(89.5))
    assert col[5] <= 89.5 and col.min() == pytest.approx(86.5)  # at most trench_depth below the saddle
    assert ((col < 100) == (level[:, 15] < 100)).all()  # same length


def test_cap_basins_refuses_other_dtypes_with_a_clear_error():
    """float64 elevations used to fail deep in numba's typing; now a ValueError names the fix."""
    grid = Grid(0.0, 10.0, 1.0, 10, 10)
    skel = SimpleNamespace(n_peaks=1, node_xyz=np.array([[5.5, 4.5, 9.0]]), edges=np.zeros((0, 3)))
    z = np.zeros((10, 10))
    with pytest.raises(ValueError, match="float32"):
        cap_basins(z, grid, skel, floor=np.full(z.shape, -np.inf, np.float32))
