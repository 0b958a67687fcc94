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
