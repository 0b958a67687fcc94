"""Terrain (raster) features of disks: landform statistics of the DEM cells within each disk.

Peak tables say nothing about the slopes, valleys and drainage between the peaks; a DEM
does. When the input has a DEM, a feature set with ``terrain=True`` adds, per disk
(:data:`TERRAIN_GROUPS`), statistics of the cells whose centre lies within R of the
disk centre, the same quantities (:mod:`orokit.metrics.landform`) that :mod:`orokit.validate.landform` compares between a
real and a synthetic DEM:

- slope quantiles (degrees, central differences);
- local relief (max - min) in ~1 km and ~5 km windows (km);
- Laplacian curvature: quantiles and inter-quartile range (1/km);
- hypsometry: elevation normalised by the disk's min and max (mean = hypsometric
  integral, quantiles);
- spectral slope beta over 0.5 km ... min(10 km, 2 R) of the square around the disk
  (:func:`orokit.metrics.landform.spectral_slope`, mean of the square and its transpose);
- drainage share: cells draining more than 1 km2 (fastscapelib single-direction flow
  routing with priority flood over the whole DEM, outlets on its border).

Every field is computed once per DEM (:func:`terrain_fields`), then cut per disk. All
values are unchanged by rotating the DEM by 90 degrees or flipping it (square cells)
up to floating point and flow-routing ties. Slopes and curvatures depend on the cell
size, so the DEM is first averaged over blocks of whole cells to about the feature set's
``terrain_cell_size_m`` (90 m: a 30 m DEM over 3 x 3 cells, SRTM-3 kept as it is).
"""
from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from orokit.errors import InputError
from orokit.sampling.feature_sets import TERRAIN_COLUMNS, TERRAIN_GROUPS

if TYPE_CHECKING:  # pragma: no cover
    import pandas as pd
    import xarray as xr

_SQ = (0.1, 0.25, 0.5, 0.75, 0.9)
_RQ = (0.25, 0.5, 0.75, 0.9)
_HQ = (0.25, 0.5, 0.75)
__all__ = ["TERRAIN_GROUPS", "TERRAIN_COLUMNS", "TerrainFields", "coarsen_dem", "disk_terrain_vector", "terrain_fields", "terrain_matrix"]



@dataclasses.dataclass(frozen=True)
class TerrainFields:
    """Per-cell fields of one DEM (:func:`terrain_fields`), cut per disk by :func:`disk_terrain_vector`."""

    z: NDArray[np.float64]
    slope_deg: NDArray[np.float64]
    relief_1km: NDArray[np.float64]
    relief_5km: NDArray[np.float64]
    curvature_per_km: NDArray[np.float64]
    channel: NDArray[np.bool_]
    dx_m: NDArray[np.float64]  # east-west cell size per row
    dy_m: float
    transform: Any


def coarsen_dem(dem: xr.DataArray, cell_size_m: float | None) -> xr.DataArray:
    """``dem`` averaged over blocks of ``f x f`` cells, ``f = round(cell_size_m / cell)`` (>= 1; the
    cell measured at the centre row), so DEMs of 30 m and 90 m give comparable slopes; a block
    touching nodata is nodata, trailing rows / columns that fill no block are dropped. Returns
    ``dem`` itself when ``f`` is 1 or ``cell_size_m`` is None."""
    from affine import Affine

    from orokit.raster.shade import row_cell_sizes_m

    if cell_size_m is None:
        return dem
    dxr, dy = row_cell_sizes_m(dem)
    cell = float(np.sqrt(float(dxr[len(dxr) // 2]) * float(dy)))
    f = max(int(round(cell_size_m / cell)), 1)
    if f == 1:
        return dem
    z = np.asarray(dem.values, dtype=np.float64)
    ny, nx = (z.shape[0] // f) * f, (z.shape[1] // f) * f
    if min(ny, nx) < 3 * f:
        raise InputError(f"terrain features: the DEM ({z.shape[1]} x {z.shape[0]} cells of {cell:.1f} m) is too small "
                         f"to average to {cell_size_m:g} m cells")
    zc = z[:ny, :nx].reshape(ny // f, f, nx // f, f).mean(axis=(1, 3))
    t = dem.rio.transform() * Affine.scale(f)
    import xarray as xr

    crs = dem.rio.crs
    from orokit.geodesy import cell_size_attrs

    # the coarse cell size in the attrs (not the input's)
    attrs = {k: v for k, v in dem.attrs.items() if k not in ("cell_size_m", "cell_size_deg")}
    attrs.update(cell_size_attrs(t, None if dem.attrs.get("local_grid") else crs))
    out = xr.DataArray(zc, dims=("y", "x"), attrs=attrs,
                       coords={"y": t.f + t.e * (np.arange(zc.shape[0]) + 0.5),
                               "x": t.c + t.a * (np.arange(zc.shape[1]) + 0.5)})
    if crs is not None:
        out = out.rio.write_crs(crs)
    return out.rio.write_transform(t)


def terrain_fields(dem: xr.DataArray, *, cell_size_m: float | None = None) -> TerrainFields:
    """Slope, relief, curvature and channel fields of a DEM (metres; NaN = nodata), computed on the
    DEM averaged to about ``cell_size_m`` (:func:`coarsen_dem`; None: the DEM's own cells)."""
    from orokit.metrics.landform import CHANNEL_AREA_M2, drainage_area, laplacian, slope_and_relief
    from orokit.raster.shade import row_cell_sizes_m

    dem = coarsen_dem(dem, cell_size_m)
    z = np.asarray(dem.values, dtype=np.float64)
    if z.ndim != 2 or min(z.shape) < 3:
        raise InputError(f"terrain features need a 2-D DEM of at least 3 x 3 cells; got shape {z.shape}")
    slope, r1 = slope_and_relief(dem, window_m=1000.0)
    _, r5 = slope_and_relief(dem, window_m=5000.0)
    dxr, dy = row_cell_sizes_m(dem)
    dxr = np.asarray(dxr, dtype=np.float64)
    area, _ = drainage_area(z, float(np.mean(dxr)), float(dy))
    return TerrainFields(z=z, slope_deg=slope, relief_1km=r1 / 1000.0, relief_5km=r5 / 1000.0,
                         curvature_per_km=1000.0 * laplacian(z, dxr, float(dy)),
                         channel=(area > CHANNEL_AREA_M2) & np.isfinite(z), dx_m=dxr, dy_m=float(dy),
                         transform=dem.rio.transform())


def _q(v: NDArray[np.float64], qs: tuple[float, ...]) -> NDArray[np.float64]:
    v = v[np.isfinite(v)]
    return np.quantile(v, qs) if len(v) else np.zeros(len(qs))


def disk_terrain_vector(fields: TerrainFields, row: float, col: float, radius_m: float) -> NDArray[np.float64]:
    """The :data:`TERRAIN_COLUMNS` of the cells within ``radius_m`` of the cell position (``row``, ``col``),
    cell centres at integers. Every value is finite (zeros for a disk without valid cells)."""
    from orokit.metrics.landform import FLAT_SLOPE_DEG, spectral_slope

    ny, nx = fields.z.shape
    kr = int(np.ceil(radius_m / fields.dy_m))
    r0, r1 = max(int(np.floor(row)) - kr, 0), min(int(np.ceil(row)) + kr + 1, ny)
    rows = np.arange(r0, r1)
    dx = fields.dx_m[rows]
    kc = int(np.ceil(radius_m / float(dx.min()))) if len(rows) else 0
    c0, c1 = max(int(np.floor(col)) - kc, 0), min(int(np.ceil(col)) + kc + 1, nx)
    cols = np.arange(c0, c1)
    d2 = ((rows[:, None] - row) * fields.dy_m) ** 2 + ((cols[None, :] - col) * dx[:, None]) ** 2
    inside = d2 <= radius_m**2
    win = (slice(r0, r1), slice(c0, c1))
    z = fields.z[win]
    inside &= np.isfinite(z)
    if not inside.any():
        return np.zeros(len(TERRAIN_COLUMNS))
    zi = z[inside]
    slope = fields.slope_deg[win][inside]
    lo, hi = float(zi.min()), float(zi.max())
    hyps = (zi - lo) / (hi - lo) if hi > lo else np.zeros_like(zi)
    curv = _q(fields.curvature_per_km[win][inside], (0.1, 0.25, 0.75, 0.9))
    band = (500.0, min(10_000.0, 2.0 * radius_m))
    beta = np.nan
    if band[1] > 2 * band[0]:  # the window and its transpose: rfft2's half plane then does not depend on orientation
        mdx = float(np.mean(dx))
        beta = 0.5 * (spectral_slope(z, (mdx, fields.dy_m), wavelengths_m=band)
                      + spectral_slope(z.T, (fields.dy_m, mdx), wavelengths_m=band))
    ok_slope = slope[np.isfinite(slope)]
    parts = [
        _q(slope, _SQ), [float(np.mean(ok_slope < FLAT_SLOPE_DEG)) if len(ok_slope) else 0.0],
        _q(fields.relief_1km[win][inside], _RQ), _q(fields.relief_5km[win][inside], (0.5, 0.9)),
        [curv[0], curv[3], curv[2] - curv[1]],
        [float(hyps.mean())], _q(hyps, _HQ),
        [beta if np.isfinite(beta) else 0.0],
        [float(fields.channel[win][inside].mean())],
    ]
    return np.concatenate([np.asarray(p, dtype=float) for p in parts])


def terrain_matrix(dem: xr.DataArray, disks: pd.DataFrame, *, cell_size_m: float | None = None,
                   fields: TerrainFields | None = None) -> NDArray[np.float64]:
    """Terrain features (one row per disk of ``disks``: columns x, y, radius_m in the DEM's CRS) of the DEM
    averaged to about ``cell_size_m`` (or of ``fields`` already computed)."""
    fields = fields if fields is not None else terrain_fields(dem, cell_size_m=cell_size_m)
    if len(disks) == 0:
        return np.zeros((0, len(TERRAIN_COLUMNS)))
    inv = ~fields.transform
    out = []
    for x, y, r in disks[["x", "y", "radius_m"]].to_numpy(dtype=float):
        c, rr = inv * (x, y)  # fractional column, row from the top-left corner
        out.append(disk_terrain_vector(fields, rr - 0.5, c - 0.5, r))
    return np.vstack(out)
