"""Belhadj 2007 backend: ridge and river skeleton, inverse midpoint displacement, then MD.

F. Belhadj, *Terrain modeling: a constrained fractal model*, AFRIGRAPH 2007
(doi:10.1145/1294685.1294717). From a Divide Tree, the skeleton is its ridges (elevation
linear from each peak to its saddle) and the rivers of :func:`orokit.generators.base.tree_rivers`;
the paper's particle skeleton is not implemented (see ``skeleton``).
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import xarray as xr

from orokit.errors import InputError
from orokit.generators import _belhadj_kernels as _k
from orokit.generators.base import as_dataarray, check_crs, tree_arrays
from orokit.raster.rasterize import Grid
from orokit.raster.rivers import RiverNetwork

logger = logging.getLogger(__name__)

__all__ = ["BelhadjParams", "render", "tree_skeleton", "interpolate", "padded_size"]

_SUBDIVISIONS = ("triangle-edge", "diamond-square")
#: kernel mode of each subdivision
MODE = {"diamond-square": 0, "triangle-edge": 1}


@dataclass(frozen=True)
class BelhadjParams:
    """Parameters of the Belhadj 2007 backend.

    subdivision : ``triangle-edge`` (the paper's Fig. 4) or ``diamond-square``; both
        are named by the paper (§3.2), which gives no default.
    displacement_m_per_cell : scale of the paper's unitless displacement: a cell at mean
        distance ``d`` cells from its children (MDI) or parents (MD) moves by
        ``displacement_m_per_cell * d^hurst * U[-1, 1]`` metres (orokit's choice: the
        paper's ``d/n * urand()`` has no unit). Default 2 m per cell.
    hurst : exponent of the distance; 1 is the paper's linear rule (MDI, §3.3), values
        below 1 give rougher small scales and smoother large ones (orokit option).
    mdi : run MDI before MD (the paper); ``False`` is plain MD on the skeleton (Fig. 3).
    rivers : burn the rivers into the skeleton (the paper's RIVER cells).
    skeleton : ``tree`` (ridges of the Divide Tree + rivers). The paper's own particle
        skeleton is not implemented in orokit.
    """

    subdivision: str = field(default="triangle-edge", metadata={"choices": _SUBDIVISIONS})
    displacement_m_per_cell: float = 2.0
    hurst: float = 1.0
    mdi: bool = True
    rivers: bool = True
    skeleton: str = field(default="tree", metadata={"choices": ("tree",)})

    def __post_init__(self) -> None:
        if self.subdivision not in _SUBDIVISIONS:
            raise InputError(f"subdivision={self.subdivision!r} is not one of {', '.join(_SUBDIVISIONS)}")
        if not (self.displacement_m_per_cell >= 0 and np.isfinite(self.displacement_m_per_cell)):
            raise InputError(f"displacement_m_per_cell must be a finite number >= 0, got {self.displacement_m_per_cell!r}")
        if not (0.0 < self.hurst <= 2.0):
            raise InputError(f"hurst must be in (0, 2], got {self.hurst!r}")
        if self.skeleton != "tree":
            raise InputError(f"skeleton={self.skeleton!r}: only 'tree' is implemented "
                             "(the paper's particle skeleton is not available in orokit)")


def padded_size(ny: int, nx: int) -> int:
    """Side ``2^k + 1`` (k >= 1) of the square MD grid holding a ``ny x nx`` grid.

    >>> padded_size(2000, 1500), padded_size(3, 3), padded_size(1, 1)
    (2049, 3, 3)
    """
    m = max(int(ny), int(nx), 2)
    k = max(int(np.ceil(np.log2(m - 1))), 1)
    return 2**k + 1


def _densify(p0: np.ndarray, p1: np.ndarray, z0: np.ndarray, z1: np.ndarray, step: float):
    """Points every ``step`` (at most) along segments p0-p1 with linear elevations."""
    length = np.hypot(*(p1 - p0).T) if p0.size else np.zeros(0)
    k = np.maximum(np.ceil(length / step).astype(np.int64), 1) + 1
    seg = np.repeat(np.arange(p0.shape[0]), k)
    first = np.repeat(np.cumsum(k) - k, k)
    t = (np.arange(seg.size) - first) / np.repeat(k - 1, k)
    xy = p0[seg] + t[:, None] * (p1[seg] - p0[seg])
    return xy, z0[seg] + t * (z1[seg] - z0[seg])


def tree_skeleton(tree, rivers: RiverNetwork | None, grid: Grid) -> tuple[np.ndarray, np.ndarray]:
    """Skeleton DEM of a tree on ``grid``: ``(z, state)`` with state 1 on RIDGE/RIVER cells.

    Ridge pieces peak -> saddle are sampled every half cell with linear elevation; a cell
    takes the highest ridge sample in it; peak and saddle cells get their exact
    elevation. River edges (bed elevations linear between nodes) fill the cells no ridge
    crosses, with the lowest sample. Other cells are NULL (state 0, z NaN).
    """
    a = tree_arrays(tree)
    z = np.full((grid.ny, grid.nx), -np.inf)
    step = 0.5 * grid.cell_size_m
    if a.edges.size:
        pk = np.concatenate([a.edges[:, 0], a.edges[:, 1]])
        sd = np.concatenate([a.edges[:, 2], a.edges[:, 2]])
        xy, h = _densify(a.peaks[pk, :2], a.saddles[sd, :2], a.peaks[pk, 2], a.saddles[sd, 2], step)
        row, col, ok = grid.cell_of(xy)
        np.maximum.at(z, (row[ok], col[ok]), h[ok])
    ridge = np.isfinite(z)
    if rivers is not None and rivers.n_nodes:
        e = rivers.edges()
        if e.size:
            xy, h = _densify(rivers.xy[e[:, 0]], rivers.xy[e[:, 1]], rivers.elevation[e[:, 0]],
                             rivers.elevation[e[:, 1]], step)
            row, col, ok = grid.cell_of(xy)
            ok &= ~ridge[row.clip(0, grid.ny - 1), col.clip(0, grid.nx - 1)]
            zr = np.full(z.shape, np.inf)
            np.minimum.at(zr, (row[ok], col[ok]), h[ok])
            on = np.isfinite(zr)
            z[on] = zr[on]
    for pts in (a.peaks, a.saddles):
        row, col, ok = grid.cell_of(pts[:, :2])
        z[row[ok], col[ok]] = pts[ok, 2]
    state = np.where(np.isfinite(z), _k.KNOWN, _k.NULL).astype(np.uint8)
    z = np.where(np.isfinite(z), z, np.nan).astype(np.float32)
    return z, state


def interpolate(z: np.ndarray, state: np.ndarray, *, params: BelhadjParams, rng: np.random.Generator,
                timings: dict[str, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Fill the NULL cells of a skeleton DEM: MDI (optional) then MD, on the padded grid.

    ``z`` (ny, nx) float32 with NaN at NULL cells, ``state`` 1 at known cells. The grid is
    padded to ``2^k + 1`` a side (rows below and columns right of the data; no
    resampling), filled, and cropped. Returns ``(z, state)`` with state 2 for cells filled by
    MDI and 3 by MD; known cells keep their exact float32 values.
    """
    ny, nx = z.shape
    n = padded_size(ny, nx)
    zz = np.zeros((n, n))
    st = np.zeros((n, n), np.uint8)
    zz[:ny, :nx] = np.where(state == _k.KNOWN, z, 0.0)
    st[:ny, :nx] = np.where(state == _k.KNOWN, _k.KNOWN, _k.NULL)
    u = rng.uniform(-1.0, 1.0, size=(n, n)).astype(np.float32)
    mode = MODE[params.subdivision]
    scale, hurst = float(params.displacement_m_per_cell), float(params.hurst)
    t0 = time.perf_counter()
    n_mdi = _k.mdi(zz, st, u, scale, hurst, mode) if params.mdi else 0
    t1 = time.perf_counter()
    corners = np.array([zz[i, j] for i in (0, n - 1) for j in (0, n - 1) if st[i, j] != _k.NULL])
    known = st == _k.KNOWN
    corner = float(corners.mean()) if corners.size else (float(zz[known].mean()) if known.any() else 0.0)
    n_md = _k.md(zz, st, u, scale, hurst, mode, corner)
    t2 = time.perf_counter()
    if timings is not None:
        timings["mdi"] = t1 - t0
        timings["md"] = t2 - t1
    logger.info("belhadj: %d x %d padded to %d; %d cells by MDI, %d by MD", ny, nx, n, n_mdi, n_md)
    out = zz[:ny, :nx].astype(np.float32)
    keep = state == _k.KNOWN
    out[keep] = z[keep]  # bit-identical skeleton (float32 -> float64 -> float32 is exact anyway)
    return out, st[:ny, :nx].copy()


def render(tree, rivers: RiverNetwork | None, grid: Grid, rng: np.random.Generator,
           params: BelhadjParams | None = None) -> xr.DataArray:
    """Elevation raster of a Divide Tree after Belhadj 2007 (pure: no file IO).

    Notes
    -----
    1. Skeleton (:func:`tree_skeleton`): ridge cells linear from peak to saddle, river
       cells from the rivers' bed elevations; every other cell is NULL.
    2. MDI (:func:`interpolate`): from the finest subdivision level up, each NULL parent
       of known cells takes the mean of its known children plus
       ``displacement_m_per_cell * mean distance^hurst * U[-1, 1]``; the filled cells
       are known for the next level, so exactly the ancestors of skeleton cells are filled.
    3. MD fills the remaining NULL cells only, coarsest level first (mean of the parents
       plus the same displacement rule); skeleton and MDI cells are never changed.

    Borders: the grid is padded to ``2^k + 1`` cells (below and right) with no
    resampling; the padding is filled like any NULL cell and cropped.
    """
    params = params or BelhadjParams()
    crs = check_crs(tree)
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    z, state = tree_skeleton(tree, rivers if params.rivers else None, grid)
    timings["skeleton"] = time.perf_counter() - t0
    out, st = interpolate(z, state, params=params, rng=rng, timings=timings)
    counts = {"skeleton": int((st == _k.KNOWN).sum()), "mdi": int((st == _k.MDI).sum()),
              "md": int((st == _k.MD).sum())}
    return as_dataarray(out, grid, crs, {"timings": timings, "cell_counts": counts})
