"""Isolation: distance from a peak to the nearest strictly higher cell."""
from __future__ import annotations

from dataclasses import dataclass

from typing import TYPE_CHECKING, Any

import numpy as np
from affine import Affine

from orokit.errors import CRSError
from orokit.geodesy import WGS84 as _GEOD
from orokit.geodesy import CellMetric
from orokit.metrics import _kernels

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["isolation", "KernelMetric"]

SLACK = 0.012  # > max relative difference between sphere and WGS84 geodesic distances
NCAND = 64


@dataclass(frozen=True)
class KernelMetric:
    """A :class:`~orokit.geodesy.CellMetric` as the plain scalars the numba isolation kernels take.

    Geographic grids use great-circle distances for the search (refined to WGS84
    geodesics by :func:`isolation`); other grids Euclidean distances with the two
    cell sizes in metres (non-square cells and foot-based CRS are fine).
    """

    geo: bool
    dx: float  # metres per column (non-geographic)
    dy: float  # metres per row (non-geographic)
    lat0: float  # radians, top edge (geographic)
    dlat: float  # radians per row (negative for north-up)
    dlon: float  # radians per column
    transform: Affine

    @classmethod
    def of(cls, metric: CellMetric) -> "KernelMetric":
        """The kernel scalars of ``metric`` (north-up grids only)."""
        t = metric.transform
        if t.b != 0 or t.d != 0:
            raise CRSError("rotated or sheared grids are not supported; warp the DEM north-up first")
        if metric.is_geographic:
            return cls(True, 0.0, 0.0, float(np.radians(t.f)), float(np.radians(t.e)), float(np.radians(t.a)), t)
        u = metric.unit_m
        return cls(False, abs(t.a) * u, abs(t.e) * u, 0.0, 0.0, 0.0, t)

    @classmethod
    def from_grid(cls, transform: Any, crs: Any) -> "KernelMetric":
        """The kernel scalars of the grid ``transform`` in ``crs`` (None: local metric grid)."""
        return cls.of(CellMetric(transform, crs))

    @property
    def slack(self) -> float:
        return SLACK if self.geo else 0.0

    @property
    def ncand(self) -> int:
        return NCAND if self.geo else 8

    def args(self, row0: int = 0) -> tuple[bool, float, float, float, int, float, float]:
        """Kernel arguments for a block whose first row is ``row0`` (latitudes come from raster rows)."""
        return (self.geo, self.dx, self.dy, self.lat0, int(row0), self.dlat, self.dlon)


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
    metric = KernelMetric.from_grid(transform, crs)
    rows = np.asarray(rows, dtype=np.int64)
    cols = np.asarray(cols, dtype=np.int64)
    z = np.ascontiguousarray(z)
    best, cand, edge = nearest_higher(z, rows, cols, metric)
    return finish_isolation(metric, rows, cols, best, cand, z.shape[1], edge)


def nearest_higher(z: np.ndarray, rows: np.ndarray, cols: np.ndarray, metric: KernelMetric,
                   pyramid: tuple[np.ndarray, ...] | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The kernels' search of :func:`isolation`: ``(best, cand_flat, edge)`` for :func:`finish_isolation`.

    ``z`` C-contiguous, ``rows``/``cols`` int64. ``pyramid``: :func:`search_pyramid` of ``z``
    when already built (None: built here).
    """
    H, W = z.shape
    if pyramid is None:
        pyramid = search_pyramid(z)
        if pyramid is None:
            pyramid = _kernels.block_pyramid(z)
    pz = z[rows, cols].astype(np.float64)
    inf = np.full(rows.size, np.inf)
    edge = _kernels.outside_distance(rows, cols, H, W, *metric.args())
    has_nan = pyramid[0] is not z  # NaN cells are -inf in a copy
    best, cand = _kernels.nearest_query(*pyramid, rows, cols, pz, inf, *metric.args(), metric.slack, metric.ncand)
    del pyramid
    if has_nan:
        nan_d = _kernels.nearest_nan_in_block(z, rows, cols, np.minimum(edge, best), *metric.args())
        edge = np.minimum(edge, nan_d)
    return best, cand, edge


def search_pyramid(z: np.ndarray) -> tuple[np.ndarray, ...] | None:
    """The part of :func:`nearest_higher` that reads only ``z``: ``z`` and its block-maximum pyramid
    (the arguments of :func:`~orokit.metrics._kernels.nearest_query` before the queries), or None
    when ``z`` holds NaN (the search then needs a copy of ``z``, made by :func:`nearest_higher`).

    One thread, ~0.1 s at 60 M cells; ``orokit analyze`` runs it beside the tree's last steps.
    """
    if z.size and np.isnan(np.max(z)):  # max propagates NaN: no bool temporary of z's size (14 MiB at 15 M)
        return None
    # no nodata: the pyramid of z itself, in z's dtype (no NaN-free copy, no NaN pyramid)
    return (z, *_kernels.build_pyramid(z))


def finish_isolation(metric: KernelMetric, rows, cols, best, cand_flat, width, edge) -> pd.DataFrame:
    """Pick the exact nearest candidate and build the isolation table.

    ``cand_flat`` holds global flat indices (row * width + col), -1 padded: every cell
    within the search slack of the best. Distances are recomputed exactly (WGS84
    geodesic for geographic grids, Euclidean otherwise) and the nearest wins; equal
    distances go to the first cell in raster order, so results do not depend on the
    search order (in memory or chunked).
    """
    import pandas as pd

    n = rows.size
    dist = np.full(n, np.inf)
    target = np.full(n, -1, np.int64)
    pi, ci = np.nonzero(cand_flat >= 0)
    if pi.size:
        cells = cand_flat[pi, ci]
        tr, tc = cells // width, cells % width
        if metric.geo:
            t = metric.transform
            _, _, d = _GEOD.inv(
                t.c + (cols[pi] + 0.5) * t.a, t.f + (rows[pi] + 0.5) * t.e,
                t.c + (tc + 0.5) * t.a, t.f + (tr + 0.5) * t.e,
            )
            d = np.asarray(d, dtype=float)
        else:
            d = np.hypot((tr - rows[pi]) * metric.dy, (tc - cols[pi]) * metric.dx)
        order = np.lexsort((cells, d, pi))  # per peak: nearest first, ties by raster order
        first = np.ones(order.size, bool)
        first[1:] = pi[order][1:] != pi[order][:-1]
        sel = order[first]
        dist[pi[sel]] = d[sel]
        target[pi[sel]] = cells[sel]
    if metric.geo:
        edge = edge * (1.0 - SLACK)  # spherical edge distance: stay conservative
    found = target >= 0
    return pd.DataFrame(
        {
            "isolation": np.where(found, dist, np.nan),
            "isolation_row": np.where(found, target // width, -1),
            "isolation_col": np.where(found, target % width, -1),
            "isolation_exact": found & (dist < edge),
        }
    )
