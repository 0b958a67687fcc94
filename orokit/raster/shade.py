"""Hillshade of a DEM (pure function, no file IO), shared by the raster writers and the reports."""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from orokit.geodesy import CellMetric

if TYPE_CHECKING:  # pragma: no cover
    import xarray as xr

__all__ = ["hillshade", "row_cell_sizes_m"]


def row_cell_sizes_m(dem: xr.DataArray) -> tuple[NDArray[np.float64], float]:
    """East-west cell size per row and the north-south size, in metres."""
    metric = CellMetric.from_dem(dem)
    rows = np.arange(dem.sizes["y"])
    if metric.is_geographic:
        dx, dy = metric.cell_size_m(rows)
        return dx, float(np.mean(dy))
    dx, dy = metric.cell_size_m([0])
    return np.full(rows.shape, float(dx[0])), float(dy[0])


def hillshade(
    dem: xr.DataArray, *, azimuth_deg: float = 315.0, altitude_deg: float = 45.0, z_factor: float = 1.0
) -> NDArray[np.float64]:
    """Hillshade in [0, 1] (1 = facing the light), with cell sizes in metres.

    ``azimuth_deg`` is the compass direction the light comes from (clockwise from
    north, 315 = north-west). Geographic grids use each row's east-west cell size.
    NaN cells stay NaN.
    """
    z = np.asarray(dem.values, dtype=np.float64) * z_factor
    dx, dy = row_cell_sizes_m(dem)
    # rows go south, so d/dnorth = -d/drow
    dz_drow, dz_dcol = np.gradient(z) if min(z.shape) > 1 else (np.zeros_like(z), np.zeros_like(z))
    dz_dx = dz_dcol / dx[:, None]
    dz_dy = -dz_drow / dy
    az = math.radians(azimuth_deg)
    alt = math.radians(altitude_deg)
    # unit light vector (east, north, up) and surface normal (-dz/dx, -dz/dy, 1)
    lx, ly, lz = math.sin(az) * math.cos(alt), math.cos(az) * math.cos(alt), math.sin(alt)
    shade = (-dz_dx * lx - dz_dy * ly + lz) / np.sqrt(1.0 + dz_dx**2 + dz_dy**2)
    return np.clip(shade, 0.0, 1.0)
