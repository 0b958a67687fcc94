"""Per-peak orometry of a Divide Tree without a raster.

A synthesized Divide Tree has no elevation raster yet, so isolation is measured to
the nearest *higher peak of the tree* (not the nearest higher terrain cell), and the
key saddle comes from the elder-rule sweep of :meth:`DivideTree.prominence_table`.
"""
from __future__ import annotations

import logging

import numpy as np
import pandas as pd
from scipy.spatial import cKDTree

from orokit.topology.divide_tree import DivideTree

logger = logging.getLogger(__name__)

__all__ = ["tree_orometry", "nearest_higher_peak", "direction_deg"]


def direction_deg(dx: np.ndarray, dy: np.ndarray) -> np.ndarray:
    """Angle of the vector (dx, dy) in degrees counter-clockwise from east, in [0, 360)."""
    ang = np.degrees(np.arctan2(dy, dx))
    return np.mod(ang, 360.0)


def _higher(z: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """True where peak j counts as higher than peak i (ties: lower id is higher)."""
    return (z[j] > z[i]) | ((z[j] == z[i]) & (j < i))


def nearest_higher_peak(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Index of the nearest strictly higher peak of every peak (-1 when none).

    Parameters
    ----------
    x, y : planar coordinates (metres).
    z : elevations; ties are broken by id (the lower id counts as higher).

    Notes
    -----
    1. Query the ``k`` nearest neighbours with a :class:`scipy.spatial.cKDTree` and
       keep the first higher one.
    2. Peaks without a higher neighbour among the ``k`` retry with ``4k`` neighbours,
       and so on; the few left (the highest peaks) are solved by brute force over the
       higher peaks, so the total cost stays close to O(n log n).
    """
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    z = np.asarray(z, float)
    n = x.size
    out = np.full(n, -1, np.int64)
    if n < 2:
        return out
    pts = np.column_stack([x, y])
    tree = cKDTree(pts)
    todo = np.arange(n)
    k = 16
    while todo.size and k < n:
        _, nb = tree.query(pts[todo], k=min(k, n))
        nb = np.atleast_2d(nb)
        hi = _higher(z, todo[:, None], nb) & (nb < n)
        found = hi.any(axis=1)
        first = np.argmax(hi, axis=1)
        out[todo[found]] = nb[found, first[found]]
        todo = todo[~found]
        k *= 4
    for i in todo:  # only the few highest peaks reach here
        cand = np.flatnonzero(_higher(z, np.full(n, i), np.arange(n)))
        if cand.size:
            d2 = (x[cand] - x[i]) ** 2 + (y[cand] - y[i]) ** 2
            out[i] = cand[np.argmin(d2)]
    return out


def tree_orometry(tree: DivideTree) -> pd.DataFrame:
    """Prominence, dominance, key saddle and isolation of every peak of ``tree``.

    Returns
    -------
    DataFrame aligned with ``tree.peaks.index`` with columns ``prominence``,
    ``key_saddle`` (-1 for roots), ``parent`` (-1 for roots), ``dominance``,
    ``saddle_x``, ``saddle_y``, ``saddle_elevation``, ``saddle_distance``,
    ``saddle_direction`` (NaN for roots), ``isolation`` (metres, NaN when no higher
    peak exists), ``isolation_peak``, ``isolation_x``, ``isolation_y``,
    ``isolation_direction`` (degrees counter-clockwise from east).
    """
    table = tree.prominence_table()
    x = tree.peaks["x"].to_numpy(float)
    y = tree.peaks["y"].to_numpy(float)
    z = tree.peaks["elevation"].to_numpy(float)
    ks = table["key_saddle"].to_numpy()
    has = ks >= 0
    sx = np.full(z.size, np.nan)
    sy = np.full(z.size, np.nan)
    sz = np.full(z.size, np.nan)
    sx[has] = tree.saddles["x"].to_numpy(float)[ks[has]]
    sy[has] = tree.saddles["y"].to_numpy(float)[ks[has]]
    sz[has] = tree.saddles["elevation"].to_numpy(float)[ks[has]]
    out = table.copy()
    with np.errstate(divide="ignore", invalid="ignore"):
        out["dominance"] = np.where(z > 0, table["prominence"].to_numpy() / z, np.nan)
    out["saddle_x"], out["saddle_y"], out["saddle_elevation"] = sx, sy, sz
    out["saddle_distance"] = np.hypot(sx - x, sy - y)
    out["saddle_direction"] = direction_deg(sx - x, sy - y)
    near = nearest_higher_peak(x, y, z)
    ok = near >= 0
    ix = np.where(ok, x[np.maximum(near, 0)], np.nan)
    iy = np.where(ok, y[np.maximum(near, 0)], np.nan)
    out["isolation"] = np.hypot(ix - x, iy - y)
    out["isolation_peak"] = near
    out["isolation_x"], out["isolation_y"] = ix, iy
    out["isolation_direction"] = direction_deg(ix - x, iy - y)
    return out
