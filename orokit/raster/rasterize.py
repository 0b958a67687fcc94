"""Rasterization of a TIN (barycentric interpolation at cell centres) and line burning."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from orokit.errors import InputError
from orokit.raster import _kernels
from orokit.raster.tin import TIN

__all__ = ["Grid", "as_extent", "make_grid", "rasterize_tin", "burn_max", "MAX_CELLS"]

#: largest raster render_elevation accepts by default (4 bytes per cell, ~8 copies in flight)
MAX_CELLS = 100_000_000


@dataclass(frozen=True)
class Grid:
    """A north-up grid: top-left corner ``(x0, y0)``, square cells ``cell_size_m`` metres."""

    x0: float
    y0: float
    cell_size_m: float
    ny: int
    nx: int

    @property
    def extent(self) -> tuple[float, float, float, float]:
        return (self.x0, self.y0 - self.ny * self.cell_size_m, self.x0 + self.nx * self.cell_size_m, self.y0)

    def centres(self) -> tuple[np.ndarray, np.ndarray]:
        """Cell-centre x (nx,) and y (ny,) coordinates."""
        x = self.x0 + (np.arange(self.nx) + 0.5) * self.cell_size_m
        y = self.y0 - (np.arange(self.ny) + 0.5) * self.cell_size_m
        return x, y

    def cell_of(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Row, col of points and a mask of those inside the grid."""
        col = np.floor((xy[:, 0] - self.x0) / self.cell_size_m).astype(np.int64)
        row = np.floor((self.y0 - xy[:, 1]) / self.cell_size_m).astype(np.int64)
        ok = (row >= 0) & (row < self.ny) & (col >= 0) & (col < self.nx)
        return row, col, ok


def as_extent(extent: Any) -> tuple[float, float, float, float]:
    """``(xmin, ymin, xmax, ymax)`` as four floats; :class:`InputError` for anything else."""
    try:
        values = [float(v) for v in extent]
    except (TypeError, ValueError):
        raise InputError(f"extent must be four numbers (xmin, ymin, xmax, ymax), got {extent!r}") from None
    if len(values) != 4:
        raise InputError(f"extent must be four numbers (xmin, ymin, xmax, ymax), got {extent!r}")
    return values[0], values[1], values[2], values[3]


def make_grid(extent: tuple[float, float, float, float], cell_size_m: float, *, max_cells: int = MAX_CELLS) -> Grid:
    """Grid covering ``extent = (xmin, ymin, xmax, ymax)`` with cells of ``cell_size_m``.

    Raises :class:`InputError` before anything is allocated when the resolution is not a
    positive finite number, the extent is empty, or the grid would exceed ``max_cells``.
    """
    try:
        res = float(cell_size_m)
    except (TypeError, ValueError):
        raise InputError(f"resolution must be a number of metres, got {cell_size_m!r}") from None
    if not math.isfinite(res) or res <= 0:
        raise InputError(f"resolution must be a positive finite number of metres, got {cell_size_m!r}")
    xmin, ymin, xmax, ymax = (float(v) for v in extent)
    if not all(math.isfinite(v) for v in (xmin, ymin, xmax, ymax)) or xmax <= xmin or ymax <= ymin:
        raise InputError(f"extent must be finite (xmin, ymin, xmax, ymax) with xmax > xmin and ymax > ymin, got {extent!r}")
    nx = max(int(round((xmax - xmin) / res)), 1)
    ny = max(int(round((ymax - ymin) / res)), 1)
    if (xmax - xmin) / res < 1 or (ymax - ymin) / res < 1:
        raise InputError(
            f"resolution {res:g} m is coarser than the extent ({xmax - xmin:g} x {ymax - ymin:g} m); "
            "choose a resolution smaller than the domain"
        )
    if nx * ny > max_cells:
        raise InputError(
            f"a {nx} x {ny} raster ({nx * ny:,} cells) at {res:g} m exceeds the limit of {max_cells:,} cells; "
            "use a coarser resolution (--resolution) or a smaller domain (--size, --extent); from Python, "
            "render_elevation(..., max_cells=N) raises the limit"
        )
    return Grid(xmin, ymax, res, ny, nx)


def rasterize_tin(tin: TIN, grid: Grid) -> np.ndarray:
    """Elevation of the TIN at every cell centre of ``grid`` (float32, NaN outside the TIN)."""
    return _kernels.rasterize_triangles(
        np.ascontiguousarray(tin.xy[:, 0]), np.ascontiguousarray(tin.xy[:, 1]),
        np.ascontiguousarray(tin.z), np.ascontiguousarray(tin.triangles),
        float(grid.x0), float(grid.y0), float(grid.cell_size_m), int(grid.ny), int(grid.nx),
    )


def burn_max(z: np.ndarray, grid: Grid, xy: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Raise the cells containing points ``xy`` to at least ``h`` (in place); returns ``z``."""
    row, col, ok = grid.cell_of(xy)
    np.maximum.at(z, (row[ok], col[ok]), h[ok].astype(z.dtype))
    return z


def set_cells(z: np.ndarray, grid: Grid, xy: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Set the cells containing points ``xy`` to ``h`` (in place); returns ``z``."""
    row, col, ok = grid.cell_of(xy)
    z[row[ok], col[ok]] = h[ok].astype(z.dtype)
    return z
