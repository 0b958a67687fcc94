"""Per-peak orometry of a Divide Tree without a raster.

A synthesized Divide Tree has no elevation raster yet, so isolation is measured to
the nearest *higher peak of the tree* (not the nearest higher terrain cell), and the
key saddle comes from the elder-rule sweep of :meth:`DivideTree.prominence_table`.
"""
from __future__ import annotations

import logging
from typing import Any

import numpy as np
import pandas as pd
from affine import Affine
from scipy.spatial import cKDTree

from orokit.topology.divide_tree import DivideTree

logger = logging.getLogger(__name__)

__all__ = ["tree_orometry", "nearest_higher_peak", "neighbour_gradients", "direction_deg", "planar_xy"]


def neighbour_gradients(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """``|h_p - h_q| / d(p, q)`` from every peak p to its nearest peak q (planar metres; m/m).

    Peaks sharing a position with another are left out (no direction to divide by).

    >>> neighbour_gradients(np.array([0.0, 100, 400]), np.zeros(3), np.array([10.0, 30, 0]))
    array([0.2, 0.2, 0.1])
    """
    x, y, z = (np.asarray(v, float) for v in (x, y, z))
    if x.size < 2:
        return np.empty(0)
    pts = np.column_stack([x, y])
    d, j = cKDTree(pts).query(pts, k=2)
    ok = d[:, 1] > 0
    return np.abs(z - z[j[:, 1]])[ok] / d[ok, 1]


def planar_xy(x: np.ndarray, y: np.ndarray, crs: Any = None) -> tuple[np.ndarray, np.ndarray]:
    """Planar metric coordinates for neighbour searches and planar geometry.

    Geographic CRS (lon/lat): a local azimuthal equidistant projection centred on the
    points' bounding-box centre (:func:`orokit.sampling.disks.local_metric_crs`);
    projected CRS: x/y times the CRS's linear unit; None: x/y as they are (metres).
    """
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    if crs is None:
        return x, y
    from orokit.geodesy import CellMetric

    metric = CellMetric(Affine.identity(), crs)
    if not metric.is_geographic:
        u = metric.unit_m
        return (x, y) if u == 1.0 else (x * u, y * u)
    from pyproj import Transformer

    from orokit.sampling.disks import local_metric_crs

    ok = np.isfinite(x) & np.isfinite(y)
    if not ok.any():
        return x.copy(), y.copy()
    lon, lat = metric.lonlat(x, y)
    lon0 = 0.5 * (np.nanmin(lon) + np.nanmax(lon))
    lat0 = 0.5 * (np.nanmin(lat) + np.nanmax(lat))
    to_local = Transformer.from_crs("EPSG:4326", local_metric_crs(lon0, lat0), always_xy=True)
    px, py = to_local.transform(lon, lat)
    return np.asarray(px, float), np.asarray(py, float)


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
    x, y : planar coordinates (metres; see :func:`planar_xy` for lon/lat).
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
    ``key_saddle`` (-1 for roots), ``island_parent`` (-1 for roots), ``dominance``,
    ``saddle_x``, ``saddle_y``, ``saddle_elevation``, ``saddle_distance``,
    ``saddle_direction`` (NaN for roots), ``isolation`` (metres, NaN when no higher
    peak exists), ``isolation_peak``, ``isolation_x``, ``isolation_y``,
    ``isolation_direction`` (degrees counter-clockwise from east).
    """
    from orokit.geodesy import point_distance
    from orokit.metrics.disk import dominance

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
    out["dominance"] = dominance(z, table["prominence"].to_numpy(float))
    out["saddle_x"], out["saddle_y"], out["saddle_elevation"] = sx, sy, sz
    out["saddle_distance"], out["saddle_direction"] = point_distance(x, y, sx, sy, crs=tree.crs)
    near = nearest_higher_peak(*planar_xy(x, y, tree.crs), z)
    ok = near >= 0
    ix = np.where(ok, x[np.maximum(near, 0)], np.nan)
    iy = np.where(ok, y[np.maximum(near, 0)], np.nan)
    iso, iso_dir = point_distance(x, y, ix, iy, crs=tree.crs)
    out["isolation"] = np.where(ok, iso, np.nan)
    out["isolation_peak"] = near
    out["isolation_x"], out["isolation_y"] = ix, iy
    out["isolation_direction"] = iso_dir
    return out
