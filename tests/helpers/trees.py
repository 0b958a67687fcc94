"""Small hand-made Divide Trees for the generator tests."""
from __future__ import annotations

import numpy as np

from orokit.topology.divide_tree import DivideTree


def small_tree(crs=None) -> DivideTree:
    """Five peaks in an 8 x 8 km square (A 1500 m is the highest), four ridges."""
    peaks = np.array([
        [2000.0, 2000.0, 1500.0],  # 0 A
        [6000.0, 2500.0, 1300.0],  # 1 B
        [4000.0, 6000.0, 1400.0],  # 2 C
        [1500.0, 6200.0, 1100.0],  # 3 D
        [6500.0, 6500.0, 1000.0],  # 4 E
    ])
    saddles = np.array([
        [4000.0, 2200.0, 1100.0],  # A-B
        [3000.0, 4000.0, 1200.0],  # A-C
        [2800.0, 6100.0, 950.0],   # C-D
        [5300.0, 6300.0, 900.0],   # C-E
    ])
    edges = np.array([[0, 1, 0], [0, 2, 1], [2, 3, 2], [2, 4, 3]])
    return DivideTree.from_arrays(peaks, saddles, edges, crs=crs, attrs={"extent": [0.0, 0.0, 8000.0, 8000.0]})


#: :func:`small_tree`'s prominences, written by hand: A 1500 (its root), B 200, C 200, D 150, E 100
SMALL_TREE_PROMINENCES = (1500.0, 200.0, 200.0, 150.0, 100.0)


def assert_keeps_small_tree(dem, *, atol: float = 6.0):
    """A render of :func:`small_tree` analysed at 30 m: every peak found within 100 m, no other one, and the
    prominences the hand-written ones within ``atol`` (a 50 m cell beside a saddle may pass up to about
    slope x cell / 2 above it). Returns the comparison."""
    import orokit
    from orokit.validate.roundtrip import compare_peaks

    res = orokit.analyze(dem, min_prominence_m=30.0, isolation=False)
    comp = compare_peaks(small_tree(), res.peaks, min_prominence_m=30.0, distance_tol_m=100.0)
    assert comp.recovered_share == 1.0 and len(comp.extra) == 0
    np.testing.assert_allclose(comp.peaks["raster_prominence"].to_numpy(), SMALL_TREE_PROMINENCES, atol=atol)
    return comp


def assert_keeps_tree(tree: DivideTree, dem, *, distance_tol_m: float = 100.0, atol: float = 6.0):
    """A render of ``tree`` analysed at 30 m: every tree peak found within ``distance_tol_m``, no other one, and the
    raster's prominences the tree's within ``atol`` (sorted). Returns the comparison."""
    import orokit
    from orokit.validate.roundtrip import compare_peaks

    res = orokit.analyze(dem, min_prominence_m=30.0, isolation=False)
    comp = compare_peaks(tree, res.peaks, min_prominence_m=30.0, distance_tol_m=distance_tol_m)
    assert comp.recovered_share == 1.0 and len(comp.extra) == 0
    np.testing.assert_allclose(np.sort(comp.peaks["raster_prominence"].to_numpy()),
                               np.sort(comp.peaks["prominence"].to_numpy()), atol=atol)
    return comp


def one_peak() -> DivideTree:
    return DivideTree.from_arrays([[4000.0, 4000.0, 900.0]], np.empty((0, 3)), np.empty((0, 3)),
                                  attrs={"extent": [0.0, 0.0, 8000.0, 8000.0]})


def collinear_tree() -> DivideTree:
    """Three peaks on one line, joined through two saddles on the same line."""
    return DivideTree.from_arrays([[1000.0, 4000.0, 800.0], [4000.0, 4000.0, 900.0], [7000.0, 4000.0, 700.0]],
                                  [[2500.0, 4000.0, 600.0], [5500.0, 4000.0, 550.0]], [[0, 1, 0], [1, 2, 1]],
                                  attrs={"extent": [0.0, 0.0, 8000.0, 8000.0]})


def empty_tree() -> DivideTree:
    return DivideTree.from_arrays(np.empty((0, 3)), np.empty((0, 3)), np.empty((0, 3)))
