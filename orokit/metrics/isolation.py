"""Isolation: distance from a peak to the nearest strictly higher cell."""
from __future__ import annotations

import numpy as np
import pandas as pd
from pyproj import CRS, Geod

from orokit.errors import CRSError
from orokit.metrics import _kernels

__all__ = ["isolation"]

_GEOD = Geod(ellps="WGS84")
_SLACK = 0.012  # > max relative difference between sphere and WGS84 geodesic distances
_NCAND = 64


def isolation(z: np.ndarray, rows: np.ndarray, cols: np.ndarray, *, transform, crs=None) -> pd.DataFrame:
    """Isolation of the peaks at ``(rows, cols)`` of the elevation grid ``z``.

    Parameters
    ----------
    z : 2-D float array (NaN = nodata).
    rows, cols : cells of the peaks.
    transform : affine transform of the grid (north-up, no rotation).
    crs : CRS of the grid; geographic CRS use WGS84 geodesic distances, anything else
        (projected, or None for a local metric grid) Euclidean distances with the two
        cell sizes of the transform (non-square cells are fine).

    Returns
    -------
    DataFrame with ``isolation`` (metres; NaN when no higher cell exists),
    ``isolation_row``, ``isolation_col`` (-1 when none) and ``isolation_exact``: True
    only when the higher cell is closer than the nearest cell outside the data
    (raster edge or NaN), since unseen terrain there could be higher and closer.

    Notes
    -----
    1. A pyramid of 2x2 block maxima is built once.
    2. For each peak a best-first search visits blocks by increasing lower bound of
       their distance, skipping blocks whose maximum is not strictly higher.
    3. Geographic grids: the search uses great-circle distances on a sphere and keeps
       every candidate within 1.2 % of the best; the WGS84 geodesic (Karney, pyproj)
       picks the exact nearest among them.
    """
    if transform.b != 0 or transform.d != 0:
        raise CRSError("rotated or sheared grids are not supported for isolation; warp the DEM north-up first")
    rows = np.asarray(rows, dtype=np.int64)
    cols = np.asarray(cols, dtype=np.int64)
    geo = bool(crs is not None and CRS.from_user_input(crs).is_geographic)
    z = np.ascontiguousarray(z, dtype=np.float64)
    if geo:
        lat0, dlat, dlon = np.radians(transform.f), np.radians(transform.e), np.radians(transform.a)
        dx = dy = 0.0
    else:
        lat0 = dlat = dlon = 0.0
        dx, dy = abs(transform.a), abs(transform.e)
    best, cand, edge = _kernels.isolation_search(
        z, rows, cols, geo, dx, dy, lat0, dlat, dlon, _SLACK if geo else 0.0, _NCAND if geo else 1
    )
    W = z.shape[1]
    target = cand[:, 0].copy()
    dist = best.copy()
    if geo and len(rows):
        # exact WGS84 geodesic among the spherical candidates
        pi, ci = np.nonzero(cand >= 0)
        cells = cand[pi, ci]
        lon_p = transform.c + (cols[pi] + 0.5) * transform.a
        lat_p = transform.f + (rows[pi] + 0.5) * transform.e
        lon_t = transform.c + (cells % W + 0.5) * transform.a
        lat_t = transform.f + (cells // W + 0.5) * transform.e
        _, _, d = _GEOD.inv(lon_p, lat_p, lon_t, lat_t)
        d = np.asarray(d, dtype=float)
        dist = np.full(len(rows), np.inf)
        order = np.lexsort((ci, d, pi))  # per peak: smallest distance first
        first = np.ones(order.size, bool)
        first[1:] = pi[order][1:] != pi[order][:-1]
        sel = order[first]
        dist[pi[sel]] = d[sel]
        target[pi[sel]] = cells[sel]
        # the edge distance is spherical: scale to be conservative
        edge = edge * (1.0 - _SLACK)
    found = np.isfinite(dist)
    out = pd.DataFrame(
        {
            "isolation": np.where(found, dist, np.nan),
            "isolation_row": np.where(found, target // W, -1),
            "isolation_col": np.where(found, target % W, -1),
            "isolation_exact": found & (dist < edge),
        }
    )
    return out
