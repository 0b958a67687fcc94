"""Distances between the landform statistics of a real and a synthetic DEM.

:func:`compare_landforms` gives the distance of each statistic of
:func:`orokit.metrics.landform.landform_statistics` between two DEMs of the same cell
size, beside its yardstick: the same distance between the north and south halves of the
real DEM, and the target ``max(2 x halves, floor)`` of issue 11. The measurements
themselves live in :mod:`orokit.metrics.landform` and are re-exported here.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from orokit.errors import InputError
from orokit.metrics.landform import (
    POWER_BANDS_M,
    LandformStatistics,
    band_power,
    landform_statistics,
    slope_and_relief,
    spectral_slope,
)

if TYPE_CHECKING:  # pragma: no cover
    import pandas as pd
    import xarray as xr

__all__ = [
    "FLOORS", "POWER_BANDS_M", "LandformStatistics", "band_power", "compare_landforms", "landform_distances", "landform_statistics",
    "slope_and_relief", "spectral_slope", "split_halves",
]

#: floors of the distances (issue 11); the target is max(2 x halves, floor)
FLOORS: dict[str, float] = {
    "slope_deg": 4.0,
    "curvature_per_km": 1.0,
    "relief_1km": 0.35,
    "spectral_slope": 0.3,
    "flat_share": 0.06,
    "hypsometry": 0.08,
}
#: what each distance measures (name -> description with units)
DISTANCES: dict[str, str] = {
    "slope_deg": "slope distribution, W1 (degrees)",
    "flat_share": "share of cells with slope < 2 deg, |difference|",
    "relief_1km": "local relief (max - min) in ~1 km windows, W1 / real median",
    "relief_5km": "local relief in ~5 km windows, W1 / real median",
    "hypsometry": "elevation normalised to [0, 1] by min/max, W1",
    "curvature_per_km": "Laplacian curvature distribution, W1 (1/km)",
    "spectral_slope": "spectral slope beta over 0.5-10 km wavelengths, |difference|",
    "low_slope_deg": "slope of the lowest tenth of the cells (valley floors, gorges), W1 (degrees)",
    "drainage_share": "share of cells draining > 1 km2, |difference|",
    "drainage_density": "drainage density of channels > 1 km2, |difference| (km/km2)",
}



def wasserstein(qa: NDArray[np.float64], qb: NDArray[np.float64]) -> float:
    """1-Wasserstein distance between two distributions given as mid-point quantiles."""
    return float(np.mean(np.abs(np.asarray(qa) - np.asarray(qb))))


def landform_distances(a: LandformStatistics, b: LandformStatistics, *, relief_scale: LandformStatistics
                       ) -> dict[str, float]:
    """Distance of every statistic between ``a`` and ``b`` (keys of :data:`DISTANCES`).

    Relief distances are divided by the median relief of ``relief_scale`` (the real DEM),
    so they are symmetric in ``a`` and ``b``.
    """
    m1 = float(np.median(relief_scale.relief_1km))
    m5 = float(np.median(relief_scale.relief_5km))
    return {
        "slope_deg": wasserstein(a.slope_deg, b.slope_deg),
        "flat_share": abs(a.flat_share - b.flat_share),
        "relief_1km": wasserstein(a.relief_1km, b.relief_1km) / max(m1, 1e-9),
        "relief_5km": wasserstein(a.relief_5km, b.relief_5km) / max(m5, 1e-9),
        "hypsometry": wasserstein(a.hypsometry, b.hypsometry),
        "curvature_per_km": wasserstein(a.curvature_per_km, b.curvature_per_km),
        "spectral_slope": abs(a.spectral_slope - b.spectral_slope),
        "low_slope_deg": wasserstein(a.low_slope_deg, b.low_slope_deg),
        "drainage_share": abs(a.drainage_share - b.drainage_share),
        "drainage_density": abs(a.drainage_density - b.drainage_density),
    }


def split_halves(dem: xr.DataArray) -> tuple[xr.DataArray, xr.DataArray]:
    """North and south halves of a DEM (rows split in the middle; the south half gets
    the odd row), each a DEM with its own coordinates and transform."""
    ny = dem.sizes["y"]
    if ny < 4:
        raise InputError(f"the real DEM needs at least 4 rows to split into halves; got {ny}")
    h = ny // 2
    return dem.isel(y=slice(0, h)), dem.isel(y=slice(h, None))


def compare_landforms(real: xr.DataArray | LandformStatistics, synthetic: xr.DataArray | LandformStatistics, *,
                      halves: tuple[LandformStatistics, LandformStatistics] | None = None,
                      rel_tol_cell: float = 0.02) -> pd.DataFrame:
    """Landform distances between a real and a synthetic DEM, with the real halves' yardstick.

    Parameters
    ----------
    real, synthetic : DEMs (or their :func:`landform_statistics`) of the same cell size.
    halves : statistics of the real DEM's north and south halves (computed from ``real``
        when it is a DEM; required when ``real`` is already statistics).
    rel_tol_cell : largest relative difference of the two cell sizes.

    Returns
    -------
    DataFrame indexed by statistic (:data:`DISTANCES`) with columns ``distance``,
    ``halves`` (north vs south of the real DEM), ``floor`` (NaN when the issue gives none),
    ``target`` = max(2 x halves, floor) and ``ok`` (distance <= target).

    Raises
    ------
    InputError : the cell sizes differ (resample one grid first), or halves are missing.
    """
    import pandas as pd

    if halves is None:
        if isinstance(real, LandformStatistics):
            raise InputError("compare_landforms needs the real DEM (or halves=) to compute the halves yardstick")
        halves = tuple(landform_statistics(h) for h in split_halves(real))  # type: ignore[assignment]
    rs = real if isinstance(real, LandformStatistics) else landform_statistics(real)
    ss = synthetic if isinstance(synthetic, LandformStatistics) else landform_statistics(synthetic)
    if abs(rs.cell_size_m - ss.cell_size_m) > rel_tol_cell * rs.cell_size_m:
        raise InputError(
            f"landforms are compared at the same cell size; the real DEM has {rs.cell_size_m:.2f} m cells, the "
            f"synthetic one {ss.cell_size_m:.2f} m: render or resample the synthetic DEM at the real cell size"
        )
    d = landform_distances(rs, ss, relief_scale=rs)
    y = landform_distances(halves[0], halves[1], relief_scale=rs)  # type: ignore[index]
    rows = []
    for k in DISTANCES:
        floor = FLOORS.get(k, float("nan"))
        target = max(2.0 * y[k], floor) if math.isfinite(floor) else 2.0 * y[k]
        rows.append({"statistic": k, "distance": d[k], "halves": y[k], "floor": floor, "target": target,
                     "ok": bool(d[k] <= target)})
    return pd.DataFrame(rows).set_index("statistic")
