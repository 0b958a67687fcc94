"""The raster grid behind an ``orokit analyze`` result, and its area on the ground.

``analysis.json`` records the grid transform (``transform``: affine a, b, c, d, e, f),
the ``shape``, the CRS (WKT) and ``crs_geographic``. :func:`analysis_grid` reads them
back (older folders without ``transform``: the local grid from ``cell_size_m``, else a
least-squares fit of the peaks' row/col to x/y, with a warning), and
:func:`grid_area_km2` measures the grid on the ground: cells of a geographic grid get
their exact area on the WGS84 ellipsoid, row by row.
"""
from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from affine import Affine
from numpy.typing import NDArray

from orokit.errors import InputError
from orokit.topology.tables import upgrade_attrs

logger = logging.getLogger(__name__)

__all__ = ["analysis_grid", "grid_area_km2", "row_cell_area_m2"]

# WGS84
_A = 6_378_137.0
_F = 1 / 298.257223563
_E2 = _F * (2 - _F)
_E = math.sqrt(_E2)


def _q(lat_deg: NDArray[np.float64]) -> NDArray[np.float64]:
    """Authalic ``q`` of the ellipsoid: the area between the equator and latitude phi
    over a longitude span of dlambda radians is ``a^2 (1 - e^2) / 2 * q(phi) * dlambda``."""
    s = np.sin(np.radians(lat_deg))
    return s / (1 - _E2 * s * s) + np.log((1 + _E * s) / (1 - _E * s)) / (2 * _E)


def row_cell_area_m2(transform: Affine, nrows: int) -> NDArray[np.float64]:
    """Area (m2) of one cell in each row of a north-up lon/lat grid (WGS84 ellipsoid).

    Examples
    --------
    >>> a = row_cell_area_m2(Affine(1.0, 0, 0, 0, -1.0, 1.0), 1)  # 1 x 1 degree at the equator
    >>> round(float(a[0]) / 1e6)
    12308
    """
    lat_edges = transform.f + transform.e * np.arange(nrows + 1, dtype=float)
    lat_edges = np.clip(lat_edges, -90.0, 90.0)
    q = _q(lat_edges)
    dlam = math.radians(abs(transform.a))
    return np.abs(np.diff(q)) * _A * _A * (1 - _E2) / 2 * dlam


def grid_area_km2(transform: Affine, crs: Any, shape: tuple[int, int],
                  valid: NDArray[np.bool_] | None = None) -> float:
    """Ground area in km2 of a grid (of its ``valid`` cells when a mask is given).

    Geographic CRS: exact ellipsoidal cell areas per row. Projected CRS: cell area in
    the CRS's linear unit converted to metres. No CRS: a local metric grid.
    """
    from orokit.geodesy import CellMetric

    nrows, ncols = (int(v) for v in shape)
    metric = CellMetric(transform, crs)
    if metric.is_geographic:
        if transform.b or transform.d:
            raise InputError("rotated geographic grids are not supported for area measurement; warp the DEM first")
        per_row = row_cell_area_m2(metric.transform, nrows)
        counts = np.full(nrows, ncols, float) if valid is None else np.asarray(valid, bool).sum(axis=1)
        return float(np.sum(per_row * counts)) / 1e6
    t = metric.transform
    cell = abs(t.a * t.e - t.b * t.d) * metric.unit_m ** 2
    n = nrows * ncols if valid is None else int(np.asarray(valid, bool).sum())
    return float(cell * n) / 1e6


def _fit_from_peaks(peaks: Any) -> Affine | None:
    if peaks is None or not {"row", "col", "x", "y"} <= set(peaks.columns) or len(peaks) < 3:
        return None
    r, c = peaks["row"].to_numpy(float), peaks["col"].to_numpy(float)
    if np.ptp(r) == 0 or np.ptp(c) == 0:
        return None
    A = np.column_stack([c + 0.5, r + 0.5, np.ones_like(c)])
    cx = np.linalg.lstsq(A, peaks["x"].to_numpy(float), rcond=None)[0]
    cy = np.linalg.lstsq(A, peaks["y"].to_numpy(float), rcond=None)[0]
    return Affine(cx[0], cx[1], cx[2], cy[0], cy[1], cy[2])


def analysis_grid(attrs: Mapping[str, Any], peaks: Any = None) -> tuple[Affine, Any, tuple[int, int]]:
    """Transform, CRS (pyproj.CRS or None) and shape of the grid an analysis ran on.

    Parameters
    ----------
    attrs : the ``analysis.json`` metadata (``AnalysisResult.attrs``).
    peaks : the analysis' peak table, only used for folders written before
        ``analysis.json`` recorded ``transform`` (a fit of row/col to x/y).

    Raises
    ------
    InputError
        No ``shape``, or no way to recover the transform.
    """
    from pyproj import CRS

    shape = attrs.get("shape")
    if not shape or len(shape) != 2:
        raise InputError("analysis.json has no 'shape': cannot tell the analysed grid; re-run `orokit analyze`")
    shape = (int(shape[0]), int(shape[1]))
    crs = attrs.get("crs")
    crs = CRS.from_user_input(crs) if crs else None
    t = attrs.get("transform")
    if t is not None:
        if len(t) < 6:
            raise InputError(f"analysis.json 'transform' must hold 6 numbers (a, b, c, d, e, f), got {t!r}")
        return Affine(*(float(v) for v in t[:6])), crs, shape
    cs = upgrade_attrs(attrs).get("cell_size_m")
    if attrs.get("local_grid") and cs:
        dx, dy = (float(cs[0]), float(cs[1])) if np.ndim(cs) else (float(cs), float(cs))
        return Affine(dx, 0.0, 0.0, 0.0, -dy, 0.0), None, shape
    fit = _fit_from_peaks(peaks)
    if fit is None:
        raise InputError("analysis.json records no grid transform and the peaks cannot recover it; "
                         "re-run `orokit analyze` with this orokit version")
    logger.warning("analysis.json records no grid transform (written by an older orokit); fitted it from the "
                   "peaks' row/col. Re-run `orokit analyze` to record it")
    return fit, crs, shape
