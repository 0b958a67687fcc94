"""Synthesis domain and user control maps (C_H elevation, C_P density, C_T type map).

Control maps are rasters in any CRS; they are resampled onto a coarse synthesis grid
covering the output domain (rioxarray / rasterio ``reproject``). Rasters without a
CRS, and plain numpy arrays, are stretched over the domain (row 0 = north).
"""
from __future__ import annotations

import logging
import warnings
from dataclasses import dataclass
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np

from orokit.errors import CRSError, InputError, OrokitWarning

logger = logging.getLogger(__name__)

__all__ = ["Domain", "make_domain", "ControlMaps", "load_control", "build_controls", "random_elevation_field",
           "random_elevation_fields", "border_density_map"]


@dataclass(frozen=True)
class Domain:
    """Rectangular output domain ``[x0, x0 + width] x [y0, y0 + height]`` in metres of ``crs``.

    ``crs`` is a projected :class:`pyproj.CRS`, or None for a local metric frame.
    The synthesis grid has ``shape`` cells (rows from north to south).
    """

    x0: float
    y0: float
    width: float
    height: float
    crs: Any = None
    shape: tuple[int, int] = (256, 256)

    @property
    def cell(self) -> tuple[float, float]:
        return self.width / self.shape[1], self.height / self.shape[0]

    @property
    def area_km2(self) -> float:
        return self.width * self.height / 1e6

    def transform(self):
        from affine import Affine

        cx, cy = self.cell
        return Affine(cx, 0.0, self.x0, 0.0, -cy, self.y0 + self.height)

    def cell_index(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Row, col of the grid cell holding each point (clipped to the grid)."""
        cx, cy = self.cell
        col = np.clip(((np.asarray(x) - self.x0) / cx).astype(np.int64), 0, self.shape[1] - 1)
        row = np.clip(((self.y0 + self.height - np.asarray(y)) / cy).astype(np.int64), 0, self.shape[0] - 1)
        return row, col

    def contains(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        x, y = np.asarray(x, float), np.asarray(y, float)
        return (x >= self.x0) & (x <= self.x0 + self.width) & (y >= self.y0) & (y <= self.y0 + self.height)


def _parse_size(size_m: Any) -> tuple[float, float]:
    if isinstance(size_m, (int, float, np.integer, np.floating)):
        w = h = float(size_m)
    else:
        w, h = (float(v) for v in size_m)
    if not (np.isfinite(w) and np.isfinite(h) and w > 0 and h > 0):
        raise InputError(f"domain size must be positive metres, got {size_m!r}")
    return w, h


def make_domain(
    size_m: Any,
    *,
    crs: Any = None,
    center: tuple[float, float] | None = None,
    center_crs: Any = "EPSG:4326",
    grid_cells: int = 256,
) -> Domain:
    """Output domain of ``size_m`` (metres, scalar or (width, height)).

    Parameters
    ----------
    crs : output CRS (EPSG code, "EPSG:xxxx", WKT, pyproj CRS). Must be projected
        (metres); without ``center`` the domain is centred on the CRS's area of use (not
        its false origin). None with ``center`` -> a local azimuthal equidistant projection
        centred on ``center`` (lon, lat); None without ``center`` -> a local frame
        with the domain's south-west corner at (0, 0).
    center : domain centre, in ``center_crs`` (default lon/lat degrees).
    grid_cells : cells along the longer side of the control grid.
    """
    from pyproj import CRS, Transformer

    w, h = _parse_size(size_m)
    n_long = int(grid_cells)
    if n_long < 8:
        raise InputError(f"grid_cells must be >= 8, got {grid_cells}")
    shape = (max(8, round(n_long * h / max(w, h))), max(8, round(n_long * w / max(w, h))))
    if crs is None and center is None:
        return Domain(0.0, 0.0, w, h, None, shape)
    if crs is None:
        assert center is not None  # the case without both returned above
        lon, lat = (float(v) for v in center)
        if center_crs is not None and CRS.from_user_input(center_crs) != CRS.from_epsg(4326):
            lon, lat = Transformer.from_crs(center_crs, "EPSG:4326", always_xy=True).transform(lon, lat)
        if not (-180 <= lon <= 180 and -90 <= lat <= 90):
            raise InputError(f"center must be lon, lat in degrees; got {center!r}")
        out = CRS.from_proj4(f"+proj=aeqd +lat_0={lat} +lon_0={lon} +x_0=0 +y_0=0 +datum=WGS84 +units=m +no_defs")
        return Domain(-w / 2, -h / 2, w, h, out, shape)
    try:
        out = CRS.from_user_input(crs)
    except Exception as exc:  # noqa: BLE001 - pyproj raises CRSError subclasses of various kinds
        raise CRSError(f"cannot understand the output CRS {crs!r} ({exc}); pass e.g. 'EPSG:32633' or WKT") from exc
    if not out.is_projected:
        raise CRSError(
            f"the output CRS {out.name!r} is not projected: synthesis works in metres. Use a projected CRS "
            "(e.g. UTM) or give only a centre lon/lat for a local projection"
        )
    from orokit.geodesy import linear_unit_m

    unit_m = linear_unit_m(out)
    if unit_m != 1.0:  # the tree and the raster would hold metres as that CRS's units
        raise CRSError(
            f"the output CRS {out.name!r} is in {out.axis_info[0].unit_name} units ({unit_m:.7g} m): synthesis works "
            "in metres. Use a projected CRS in metres (e.g. the UTM zone) or give only a centre lon/lat for a local "
            "projection"
        )
    if center is None:
        # not the CRS's false origin (often in the ocean): the centre of its area of use
        aou = out.area_of_use
        if aou is None:
            return Domain(0.0, 0.0, w, h, out, shape)
        center, center_crs = (0.5 * (aou.west + aou.east), 0.5 * (aou.south + aou.north)), "EPSG:4326"
    cx, cy = Transformer.from_crs(center_crs, out, always_xy=True).transform(*center)
    return Domain(cx - w / 2, cy - h / 2, w, h, out, shape)


@dataclass(frozen=True)
class ControlMaps:
    """Control maps on the domain grid (row 0 = north).

    density : C_P >= 0 (0 = no peaks: sea, lakes); elevation : C_H in metres or None;
    type_index : int per cell (index into the list of terrain types).
    """

    density: np.ndarray
    elevation: np.ndarray | None
    type_index: np.ndarray


def _as_dataarray(src: Any):
    import xarray as xr

    if isinstance(src, xr.DataArray):
        return src
    if isinstance(src, np.ndarray):
        return None
    from orokit.io.dem import read_raster_band

    return read_raster_band(src, what="control raster")


def load_control(src: Any, domain: Domain, *, kind: str = "density") -> np.ndarray:
    """Resample one control map onto the domain grid.

    Parameters
    ----------
    src : path, DataArray or 2-D numpy array.
    kind : "density" / "elevation" (bilinear) or "type" (nearest).

    Returns
    -------
    float array of ``domain.shape``; NaN where the source has no data.

    Raises
    ------
    InputError
        Unreadable file, not 2-D, or no overlap with the domain.
    """
    from rasterio.enums import Resampling

    name = src if isinstance(src, str) else type(src).__name__
    resampling = Resampling.nearest if kind == "type" else Resampling.bilinear
    da = _as_dataarray(src)
    crs = None
    if da is not None:
        try:
            crs = da.rio.crs
        except Exception:  # noqa: BLE001
            crs = None
    if da is not None and crs is not None and domain.crs is not None:
        try:
            out = da.astype("float64").rio.reproject(
                domain.crs, shape=domain.shape, transform=domain.transform(), resampling=resampling,
                nodata=np.nan,
            )
        except Exception as exc:  # noqa: BLE001
            raise InputError(f"cannot resample control raster {name!r} onto the domain: {exc}") from exc
        arr = np.asarray(out.values, float)
    else:
        if da is not None and crs is not None and domain.crs is None:
            warnings.warn(
                f"control raster {name!r} has a CRS but the output has none: it is stretched over the domain. "
                "Pass --crs (or a centre) to place it geographically",
                OrokitWarning, stacklevel=3,
            )
        arr = np.asarray(src if da is None else da.values, float)
        if arr.ndim != 2 or min(arr.shape) < 1:
            raise InputError(f"control map {name!r} must be a 2-D raster, got shape {arr.shape}")
        arr = _stretch(arr, domain.shape, order=0 if kind == "type" else 1)
    if not np.isfinite(arr).any():
        raise InputError(
            f"control raster {name!r} does not overlap the output domain "
            f"(x {domain.x0:.0f}..{domain.x0 + domain.width:.0f}, y {domain.y0:.0f}..{domain.y0 + domain.height:.0f}"
            f" in {domain.crs.name if domain.crs is not None else 'a local frame'}); check its CRS and the domain centre"
        )
    return arr


def _stretch(arr: np.ndarray, shape: tuple[int, int], *, order: int) -> np.ndarray:
    """Resample a grid to ``shape`` covering the same extent (cell-centre aligned)."""
    from scipy.ndimage import map_coordinates

    h, w = arr.shape
    rows = (np.arange(shape[0]) + 0.5) * h / shape[0] - 0.5
    cols = (np.arange(shape[1]) + 0.5) * w / shape[1] - 0.5
    rr, cc = np.meshgrid(np.clip(rows, 0, h - 1), np.clip(cols, 0, w - 1), indexing="ij")
    if order == 0:
        return arr[np.rint(rr).astype(int), np.rint(cc).astype(int)]
    filled = np.where(np.isfinite(arr), arr, 0.0)
    weight = map_coordinates(np.isfinite(arr).astype(float), [rr, cc], order=1, mode="nearest")
    val = map_coordinates(filled, [rr, cc], order=1, mode="nearest")
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(weight > 0.5, val / np.maximum(weight, 1e-12), np.nan)


def build_controls(
    domain: Domain,
    *,
    control_density: Any = None,
    control_elevation: Any = None,
    type_map: Any = None,
    n_types: int = 1,
) -> ControlMaps:
    """Load and check the control maps (defaults: uniform density, no C_H, type 0)."""
    shape = domain.shape
    if control_density is None:
        dens = np.ones(shape)
    else:
        dens = load_control(control_density, domain, kind="density")
        miss = ~np.isfinite(dens)
        if miss.any():
            warnings.warn(f"density control covers {100 * (1 - miss.mean()):.1f}% of the domain; "
                          "no peaks are placed outside it", OrokitWarning, stacklevel=2)
        dens = np.where(miss, 0.0, dens)
        if (dens < 0).any():
            raise InputError(f"density control has negative values (min {dens.min():g}); use values >= 0")
    elev = None
    if control_elevation is not None:
        elev = load_control(control_elevation, domain, kind="elevation")
    if type_map is None:
        types = np.zeros(shape, np.int64)
    else:
        raw = load_control(type_map, domain, kind="type")
        bad = ~np.isfinite(raw)
        if bad.any():
            warnings.warn(f"type map covers {100 * (1 - bad.mean()):.1f}% of the domain; "
                          "cells outside it get type 0", OrokitWarning, stacklevel=2)
        types = np.where(bad, 0, np.rint(np.where(bad, 0, raw))).astype(np.int64)
        if types.min() < 0 or types.max() >= n_types:
            raise InputError(
                f"type map values must be indices 0..{n_types - 1} into the list of terrain types; "
                f"found {types.min()}..{types.max()}"
            )
    if not (dens > 0).any():
        raise InputError("the density control is 0 everywhere in the domain: there is no room for peaks")
    return ControlMaps(dens.astype(float), None if elev is None else elev.astype(float), types)


def random_elevation_field(domain: Domain, elevation_hist: Any, *, correlation_m: float, rng: Any,
                           border_rank: Sequence[float] | None = None, fine_m: float = 1000.0,
                           fine_weight: float = 0.0) -> np.ndarray:
    """A smooth random C_H whose values follow ``elevation_hist`` (orokit default).

    Without a user C_H, peak elevations would be spatially uncorrelated, so high peaks
    would sit among low ones and their ridges would dip through low peaks (too much
    prominence). Gaussian-filtered white noise (standard deviation ``correlation_m``)
    is mapped by rank onto the quantiles of the type's elevation histogram.

    ``border_rank`` (a type's :func:`orokit.synthesis.disks.border_rank`): a smooth trend
    in the distance to the domain border is added to the noise before the ranking, fitted so
    the mean rank of the field in each border band matches it (a twin of a DEM cropped around
    its relief then holds its high ground inside, issue 11). None: no trend (stationary field).

    ``fine_weight`` > 0 adds a second noise filtered at ``fine_m`` with that weight (both
    normalised to unit standard deviation) before the ranking: neighbouring peaks then differ
    more in elevation (see :func:`random_elevation_fields`).
    """
    return next(random_elevation_fields(domain, elevation_hist, correlation_m=correlation_m, rng=rng,
                                        border_rank=border_rank, fine_m=fine_m, fine_weights=(fine_weight,)))


def random_elevation_fields(domain: Domain, elevation_hist: Any, *, correlation_m: float, rng: Any,
                            border_rank: Sequence[float] | None = None, fine_m: float = 1000.0,
                            fine_weights: Sequence[float] = (0.0,),
                            density: np.ndarray | None = None, valley_weight: float = 0.0) -> Iterator[np.ndarray]:
    """:func:`random_elevation_field` for each of ``fine_weights`` in turn, from the same two noises
    (lazily: a caller fitting the weight stops when it has what it needs).

    With weights all 0 the random draws are those of one field without the fine component.
    ``density`` (the C_P, >= 0, of the domain's shape): ranks are weighted by it, so the field's
    elevations at the places the peaks are drawn from (not per area) follow the histogram, and the
    border trend's band means are those of the peaks; None: every cell weighs the same.

    ``valley_weight`` v in (0, 1]: the smooth noise becomes ``(1 - v) g + v |h|`` (both standardised,
    h a second noise of the same correlation drawn after g), so the low ground follows the zero lines
    of h, a network that crosses the domain, instead of the isolated basins a ranked Gaussian field
    gives (issue 11, session 16). 0 draws nothing more.
    """
    from scipy.ndimage import gaussian_filter

    rng = np.random.default_rng(rng)
    cx, cy = domain.cell
    # a correlation longer than the grid gives one smooth blob anyway: cap the kernel there
    # (an uncapped width on a tiny domain made the filter run for minutes)
    ny, nx = domain.shape
    sigma = (min(correlation_m / cy, float(ny)), min(correlation_m / cx, float(nx)))
    base = gaussian_filter(rng.standard_normal(domain.shape), sigma=sigma, mode="wrap")
    if valley_weight > 0:
        folded = np.abs(gaussian_filter(rng.standard_normal(domain.shape), sigma=sigma, mode="wrap"))
        base = ((1.0 - valley_weight) * base / max(float(base.std()), 1e-12)
                + valley_weight * (folded - folded.mean()) / max(float(folded.std()), 1e-12))
    fine = None
    for w in fine_weights:
        noise = base
        if w > 0:
            if fine is None:
                fine = gaussian_filter(rng.standard_normal(domain.shape),
                                       sigma=(min(fine_m / cy, float(ny)), min(fine_m / cx, float(nx))), mode="wrap")
                fine = fine / max(float(fine.std()), 1e-12)
            noise = base / max(float(base.std()), 1e-12) + float(w) * fine
        if border_rank is not None:
            noise = _with_border_trend(noise, domain, np.asarray(border_rank, float), weights=density)
        if density is None:
            ranks = np.argsort(np.argsort(noise.ravel(), kind="stable"), kind="stable")
            q = (ranks + 0.5) / ranks.size
        else:
            q = _weighted_ranks(noise.ravel(), np.asarray(density, float).ravel())
        p = elevation_hist.probabilities()
        cdf = np.concatenate([[0.0], np.cumsum(p)])
        e = np.asarray(elevation_hist.edges, float)
        yield np.interp(q, cdf, e).reshape(domain.shape)


def _weighted_ranks(values: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Mid-point ranks in [0, 1] of ``values`` where each counts with its weight (equal weights:
    ``(i + 0.5) / n``)."""
    order = np.argsort(values, kind="stable")
    w = np.clip(weights[order], 0.0, None)
    cw = np.cumsum(w)
    q = np.empty(values.size)
    q[order] = (cw - 0.5 * w) / max(float(cw[-1]), 1e-300)
    return q


def _border_bands(domain: Domain) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Normalised border distance of every grid cell (flattened), its band and the bands' centres."""
    from orokit.synthesis.disks import BORDER_BANDS, border_distance

    ny, nx = domain.shape
    cx, cy = domain.cell
    xs = domain.x0 + (np.arange(nx) + 0.5) * cx
    ys = domain.y0 + (np.arange(ny) + 0.5) * cy
    gx, gy = np.meshgrid(xs, ys)
    t = border_distance(gx, gy, (domain.x0, domain.y0, domain.x0 + domain.width, domain.y0 + domain.height)).ravel()
    edges = np.asarray(BORDER_BANDS)
    mids = 0.5 * (edges[1:] + edges[:-1])
    band = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, mids.size - 1)
    return t, band, mids


def border_density_map(domain: Domain, profile: Sequence[float], *, floor: float = 0.05,
                       iterations: int = 50) -> np.ndarray:
    """A C_P on the domain grid whose mean in each border band is ``profile`` (a type's
    ``border_density``: relative peak density per :data:`~orokit.synthesis.disks.BORDER_BANDS` band).

    Linear in the distance to the border between the bands' centres (flat beyond the outer
    ones), fitted by a fixed-point iteration; at least ``floor`` times the profile's mean, so no
    band is closed to peaks. Mean 1 over the domain's cells.
    """
    target = np.asarray(profile, float)
    t, band, mids = _border_bands(domain)
    count = np.bincount(band, minlength=mids.size)
    target = target / max(float(np.dot(count, target) / max(count.sum(), 1)), 1e-12)
    low = floor * float(target.mean())
    value = target.copy()
    for _ in range(iterations):
        dens = np.maximum(np.interp(t, mids, value), low)
        mean = np.bincount(band, weights=dens, minlength=mids.size) / np.maximum(count, 1)
        err = np.where(count > 0, target - mean, 0.0)
        if np.abs(err).max() < 1e-3:
            break
        value = value + err
    dens = np.maximum(np.interp(t, mids, value), low)
    return (dens / dens.mean()).reshape(domain.shape)


def _with_border_trend(noise: np.ndarray, domain: Domain, target: np.ndarray, iterations: int = 30,
                       weights: np.ndarray | None = None) -> np.ndarray:
    """``noise`` plus a trend in the distance to the border whose band mean ranks approach ``target``.

    The trend is linear between the bands' centres (per band one offset, in units of the
    noise's standard deviation), fitted by a damped fixed-point iteration on the grid. The
    target is first shifted so its mean over the domain's cells is 0.5 (as every field's is).
    With ``weights`` (the C_P) ranks and means are weighted by it (the peaks' view of the field).
    """
    t, band, mids = _border_bands(domain)
    count = np.bincount(band, minlength=mids.size)
    wflat = None if weights is None else np.clip(np.asarray(weights, float).ravel(), 0.0, None)
    mass = count.astype(float) if wflat is None else np.bincount(band, weights=wflat, minlength=mids.size)
    z = (noise - noise.mean()) / max(float(noise.std()), 1e-12)
    z = z.ravel()
    # the field's mean rank is 0.5 whatever the trend: only the differences between bands can be
    # met, so the target is shifted to a mean of 0.5 over the domain's own band areas (masses)
    if wflat is None:
        target = np.clip(target - (np.dot(count, target) / count.sum() - 0.5), 0.02, 0.98)
    else:
        target = np.clip(target - (np.dot(mass, target) / max(float(mass.sum()), 1e-300) - 0.5), 0.02, 0.98)
    offset = np.zeros(mids.size)
    for _ in range(iterations):
        score = z + np.interp(t, mids, offset)
        if wflat is None:
            q = (np.argsort(np.argsort(score, kind="stable"), kind="stable") + 0.5) / score.size
            mean = np.bincount(band, weights=q, minlength=mids.size) / np.maximum(count, 1)
        else:
            q = _weighted_ranks(score, wflat)
            mean = np.bincount(band, weights=q * wflat, minlength=mids.size) / np.maximum(mass, 1e-300)
        err = np.where(count > 0, target - mean, 0.0)
        if np.abs(err).max() < 0.005:
            break
        offset += 4.0 * err
    return (z + np.interp(t, mids, offset)).reshape(noise.shape)
