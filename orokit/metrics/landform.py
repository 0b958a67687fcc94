"""Landform measurements of a DEM: slope, local relief, hypsometry, curvature, spectrum, drainage.

:func:`landform_statistics` summarises a DEM by the distributions and numbers a
geomorphologist looks at; :mod:`orokit.validate.landform` compares two such summaries
(real against synthetic) and :mod:`orokit.classify.terrain` turns the same per-cell
quantities into disk features, so both measure one thing one way.

Distributions are kept as ``N_QUANTILES`` mid-point quantiles, so the 1-Wasserstein
distance is the mean absolute difference of the two quantile functions
(``W1 = integral_0^1 |F^-1(u) - G^-1(u)| du``) and the statistics fit in a JSON file.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from orokit.errors import InputError
from orokit.raster.noise import radial_bins, remove_plane
from orokit.raster.shade import row_cell_sizes_m

if TYPE_CHECKING:  # pragma: no cover
    import xarray as xr

__all__ = [
    "CHANNEL_AREA_M2", "CHANNEL_BANDS_KM2", "FLAT_SLOPE_DEG", "LOW_GROUND_SHARE", "N_QUANTILES", "POWER_BANDS_M",
    "LandformStatistics", "band_power", "channel_slopes", "drainage_area", "landform_statistics", "laplacian",
    "slope_and_relief", "spectral_slope",
]

#: number of mid-point quantiles kept per distribution
N_QUANTILES = 512
#: slope below which a cell counts as flat (degrees)
FLAT_SLOPE_DEG = 2.0
#: drainage area above which a cell counts as a channel (m^2)
CHANNEL_AREA_M2 = 1.0e6
#: share of the cells, lowest first, whose slopes make the low-ground distribution (valley floors,
#: basins and the gorges near the base level)
LOW_GROUND_SHARE = 0.1
#: wavelength bands (metres) of :func:`band_power`: below 0.5 km (texture, curvature), the
#: spectral-slope range 0.5-10 km in four bands
POWER_BANDS_M: tuple[tuple[float, float], ...] = ((0.0, 300.0), (300.0, 500.0), (500.0, 1000.0),
                                                  (1000.0, 2000.0), (2000.0, 5000.0), (5000.0, 10_000.0))

@dataclass(frozen=True)
class LandformStatistics:
    """Landform summary of one DEM (see :func:`landform_statistics`).

    Distributions are ``N_QUANTILES`` mid-point quantiles; the scalars are plain numbers.
    """

    cell_size_m: float
    shape: tuple[int, int]
    slope_deg: NDArray[np.float64]
    relief_1km: NDArray[np.float64]
    relief_5km: NDArray[np.float64]
    hypsometry: NDArray[np.float64]
    curvature_per_km: NDArray[np.float64]
    flat_share: float
    spectral_slope: float
    drainage_share: float
    drainage_density: float
    relief_window_m: tuple[float, float]
    low_slope_deg: NDArray[np.float64]

    @property
    def summary(self) -> dict[str, float]:
        """Scalars a reader can compare by eye: means, medians and shares."""
        return {
            "mean_slope_deg": float(self.slope_deg.mean()),
            "p90_slope_deg": float(np.quantile(self.slope_deg, 0.9)),
            "flat_share": self.flat_share,
            "median_relief_1km_m": float(np.median(self.relief_1km)),
            "median_relief_5km_m": float(np.median(self.relief_5km)),
            "mean_hypsometry": float(self.hypsometry.mean()),
            "curvature_iqr_per_km": float(np.quantile(self.curvature_per_km, 0.75)
                                          - np.quantile(self.curvature_per_km, 0.25)),
            "spectral_slope": self.spectral_slope,
            "median_low_slope_deg": float(np.median(self.low_slope_deg)),
            "drainage_share": self.drainage_share,
            "drainage_density_km_per_km2": self.drainage_density,
        }

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in d.items()}


def _quantiles(v: NDArray[np.floating]) -> NDArray[np.float64]:
    v = np.asarray(v, dtype=np.float64).ravel()
    v = v[np.isfinite(v)]
    if v.size == 0:
        return np.full(N_QUANTILES, np.nan)
    u = (np.arange(N_QUANTILES) + 0.5) / N_QUANTILES
    return np.quantile(v, u)


def _gradient(z: NDArray[np.float64], dx: NDArray[np.float64], dy: float
              ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """dz/dx (east) and dz/dy (north) by central differences (one-sided at the edges)."""
    if min(z.shape) < 2:
        raise InputError(f"landform statistics need at least 2 x 2 cells; got {z.shape}")
    dz_drow, dz_dcol = np.gradient(z)
    return np.asarray(dz_dcol / dx[:, None], float), np.asarray(-dz_drow / dy, float)


def laplacian(z: NDArray[np.float64], dx: NDArray[np.float64], dy: float) -> NDArray[np.float64]:
    """5-point Laplacian (1/m) of ``z`` with east-west cell sizes ``dx`` per row; NaN on the border."""
    out = np.full(z.shape, np.nan)
    if min(z.shape) < 3:
        return out
    c = z[1:-1, 1:-1]
    dxx = (z[1:-1, 2:] - 2 * c + z[1:-1, :-2]) / dx[1:-1, None] ** 2
    dyy = (z[2:, 1:-1] - 2 * c + z[:-2, 1:-1]) / dy**2
    out[1:-1, 1:-1] = dxx + dyy
    return out


def _relief(z: NDArray[np.float64], window_cells: tuple[int, int]) -> NDArray[np.float64]:
    """max - min over a window centred on each cell (partial windows at the edges;
    windows touching nodata are NaN)."""
    nan = ~np.isfinite(z)
    hi = ndimage.maximum_filter(np.where(nan, np.inf, z), size=window_cells, mode="nearest")
    lo = ndimage.minimum_filter(np.where(nan, -np.inf, z), size=window_cells, mode="nearest")
    r = hi - lo
    r[~np.isfinite(r)] = np.nan
    return r


def _power_spectrum(z: NDArray[np.floating], cell_size_m: tuple[float, float]
                    ) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """Wavenumber ``|k|`` (cycles per metre) and power ``|FFT|^2`` of ``z`` (NaN filled with the
    mean, least-squares plane removed, 2-D Hann taper), on the ``rfft2`` grid; None if all NaN."""
    z = np.asarray(z, dtype=np.float64)
    ok = np.isfinite(z)
    if not ok.any():
        return None
    z = np.where(ok, z, z[ok].mean())
    z = remove_plane(z)
    ny, nx = z.shape
    z *= np.outer(np.hanning(ny), np.hanning(nx))
    power = np.abs(np.fft.rfft2(z)) ** 2
    dx, dy = cell_size_m
    kx = np.fft.rfftfreq(nx, dx)
    ky = np.fft.fftfreq(ny, dy)
    return np.hypot(kx[None, :], ky[:, None]), power


def spectral_slope(z: NDArray[np.floating], cell_size_m: tuple[float, float], *,
                   wavelengths_m: tuple[float, float] = (500.0, 10_000.0), n_bins: int = 16) -> float:
    """Spectral slope beta of the radially averaged power spectrum, ``P(k) ~ k^-beta``.

    The grid (NaN filled with the mean) is detrended by a least-squares plane and
    tapered by a 2-D Hann window; the power ``|FFT|^2`` is averaged in ``n_bins``
    log-spaced wavenumber bins between ``1 / wavelengths_m[1]`` and
    ``1 / wavelengths_m[0]`` (bins without a wavenumber are skipped), and beta is minus
    the least-squares slope of log P against log k. ``cell_size_m`` is ``(dx, dy)``.
    NaN when fewer than 3 bins hold a wavenumber (grid too small for the band).
    """
    spec = _power_spectrum(z, cell_size_m)
    if spec is None:
        return float("nan")
    k, power = spec
    kb, pb = radial_bins(k, power, (1.0 / wavelengths_m[1], 1.0 / wavelengths_m[0]), n_bins)
    if len(kb) < 3:
        return float("nan")
    slope = np.polyfit(np.log10(kb), np.log10(pb), 1)[0]
    return float(-slope)


def band_power(z: NDArray[np.floating], cell_size_m: tuple[float, float], *,
               bands_m: tuple[tuple[float, float], ...] = POWER_BANDS_M) -> NDArray[np.float64]:
    """Mean spectral power of ``z`` in wavelength bands (m^2 per Fourier coefficient).

    Same preprocessing as :func:`spectral_slope` (NaN filled with the mean, plane removed,
    2-D Hann taper); band ``(lo, hi)`` holds the wavelengths ``lo <= 1/|k| < hi`` metres.
    The ratio of two grids' band powers (same shape and cell size) says at which
    wavelengths one has more relief than the other: where beta and curvature differences
    come from. NaN for a band without a wavenumber (or an all-NaN grid).

    >>> y, x = np.mgrid[0:128, 0:128] * 100.0
    >>> p = band_power(np.sin(2 * np.pi * x / 1600.0), (100.0, 100.0))
    >>> int(np.nanargmax(p)), bool(p[3] > 10 * np.nanmax(np.delete(p, 3)))
    (3, True)
    """
    out = np.full(len(bands_m), np.nan)
    spec = _power_spectrum(z, cell_size_m)
    if spec is None:
        return out
    k, power = spec
    with np.errstate(divide="ignore"):
        wavelength = np.where(k > 0, 1.0 / k, np.inf)
    for i, (lo, hi) in enumerate(bands_m):
        sel = (wavelength >= lo) & (wavelength < hi)
        if sel.any():
            out[i] = float(power[sel].mean())
    return out


def drainage_area(z: NDArray[np.float64], dx: float, dy: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Drainage area (m^2) of every cell and the distance (m) to its receiver, both shaped like ``z``.

    Single-direction flow routing with depressions resolved by priority flood
    (fastscapelib ``SingleFlowRouter`` + ``PFloodSinkResolver``), outlets on the whole
    border; nodata cells are routed at the DEM's minimum.
    """
    area, _, dist = _routes(z, dx, dy)
    return area, dist.reshape(z.shape)


def _routes(z: NDArray[np.float64], dx: float, dy: float
            ) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.float64]]:
    """:func:`drainage_area`'s routing: area (shaped like ``z``), each cell's receiver and the distance to it
    (flat indices)."""
    import fastscapelib as fs

    ny, nx = z.shape
    grid = fs.RasterGrid([ny, nx], [dy, dx], fs.NodeStatus.FIXED_VALUE)
    graph = fs.FlowGraph(grid, [fs.SingleFlowRouter(), fs.PFloodSinkResolver()])
    filled = np.where(np.isfinite(z), z, np.nanmin(z) if np.isfinite(z).any() else 0.0)
    graph.update_routes(np.ascontiguousarray(filled))
    area = np.asarray(graph.accumulate(1.0)).reshape(z.shape)
    impl = graph.impl()
    receiver = np.asarray(impl.receivers)[:, 0].astype(np.int64)
    dist = np.asarray(impl.receivers_distance)[:, 0].astype(np.float64)
    return area, receiver, dist


#: drainage-area bands (km^2) of :func:`channel_slopes`
CHANNEL_BANDS_KM2: tuple[tuple[float, float], ...] = ((0.1, 1.0), (1.0, 10.0), (10.0, 100.0), (100.0, 1000.0))


def channel_slopes(dem: xr.DataArray, *, bands_km2: tuple[tuple[float, float], ...] = CHANNEL_BANDS_KM2,
                   reach_cells: int = 8, steep: float = 1.0) -> dict[str, dict[str, float]]:
    """Channel slope by drainage area (the slope-area relation, Flint's law ``S ~ A^-theta`` in real ranges).

    The cells are routed as :func:`drainage_area` does; a cell's channel slope is its drop to the cell
    ``reach_cells`` steps downstream over the flow distance between them (m/m; fewer steps where the path
    reaches an outlet; flat and rising reaches count as 0). Per band ``"lo-hi"`` of drainage area (km^2, ``lo <=
    A < hi``): the cells' count ``n``, the 10th / 50th / 90th / 99th percentiles ``p10 ... p99`` and the share
    steeper than ``steep`` m/m (NaN without cells). Nodata cells are left out.
    """
    z = np.asarray(dem.values, dtype=np.float64)
    dxr, dy = row_cell_sizes_m(dem)
    area, receiver, dist = _routes(z, float(np.mean(dxr)), float(dy))
    zf = z.ravel()
    down = np.arange(zf.size)
    flow = np.zeros(zf.size)
    for _ in range(int(reach_cells)):
        flow += dist[down]
        down = receiver[down]
    ok = np.isfinite(zf) & np.isfinite(zf[down]) & (flow > 0)
    slope = np.where(ok, np.maximum(zf - np.where(ok, zf[down], 0.0), 0.0) / np.where(flow > 0, flow, 1.0), np.nan)
    a = area.ravel() / 1.0e6
    out: dict[str, dict[str, float]] = {}
    for lo, hi in bands_km2:
        v = slope[ok & (a >= lo) & (a < hi)]
        q = np.quantile(v, (0.1, 0.5, 0.9, 0.99)) if v.size else np.full(4, np.nan)
        out[f"{lo:g}-{hi:g}"] = {"n": int(v.size), "p10": float(q[0]), "p50": float(q[1]), "p90": float(q[2]),
                                 "p99": float(q[3]),
                                 "steep_share": float(np.mean(v > steep)) if v.size else float("nan")}
    return out


def _drainage(z: NDArray[np.float64], dx: float, dy: float) -> tuple[float, float]:
    """Share of cells draining more than :data:`CHANNEL_AREA_M2` and drainage density (km / km2):
    a channel cell contributes the distance to its receiver (:func:`drainage_area`)."""
    area, dist = drainage_area(z, dx, dy)
    chan = area > CHANNEL_AREA_M2
    length_km = float(dist[chan].sum()) / 1000.0
    total_km2 = z.shape[0] * z.shape[1] * dx * dy / 1.0e6
    return float(chan.mean()), length_km / total_km2


def _low_ground(z: NDArray[np.float64], slope: NDArray[np.float64]) -> NDArray[np.float64]:
    """Slopes of the lowest :data:`LOW_GROUND_SHARE` of the valid cells (ties at the cut included)."""
    ok = np.isfinite(z) & np.isfinite(slope)
    if not ok.any():
        return np.empty(0)
    cut = float(np.quantile(z[ok], LOW_GROUND_SHARE))
    return slope[ok & (z <= cut)]


def _window_cells(window_m: float, dx: float, dy: float) -> tuple[int, int]:
    """Odd window size in cells (rows, cols) closest to ``window_m``, at least 3."""
    def odd(n: float) -> int:
        k = max(int(round(n)), 3)
        return k if k % 2 else k + 1
    return odd(window_m / dy), odd(window_m / dx)


def slope_and_relief(dem: xr.DataArray, *, window_m: float = 1000.0) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Per-cell slope (degrees, central differences) and local relief (m) in ~``window_m``
    windows of a DEM, as :func:`landform_statistics` computes them (NaN kept)."""
    z = np.asarray(dem.values, dtype=np.float64)
    dxr, dy = row_cell_sizes_m(dem)
    dxr = np.asarray(dxr, dtype=np.float64)
    gx, gy = _gradient(z, dxr, float(dy))
    slope = np.degrees(np.arctan(np.hypot(gx, gy)))
    return slope, _relief(z, _window_cells(window_m, float(np.mean(dxr)), float(dy)))


def landform_statistics(dem: xr.DataArray, *, relief_windows_m: tuple[float, float] = (1000.0, 5000.0)
                        ) -> LandformStatistics:
    """Landform statistics of a DEM (metres; projected, local metric or lon/lat grid).

    Notes
    -----
    Cell sizes come from the grid (:class:`orokit.geodesy.CellMetric`: per row on lon/lat grids).

    1. Slope (degrees) from central differences; flat share = slope < 2 deg.
    2. Local relief (max - min) in windows of ~1 and ~5 km (odd cell counts; partial
       windows at the edges; windows touching nodata left out).
    3. Hypsometry: elevations normalised to [0, 1] by the DEM's min and max.
    4. Laplacian curvature (5-point stencil, 1/km) on interior cells.
    5. Spectral slope beta over wavelengths 0.5-10 km (:func:`spectral_slope`).
    6. Drainage (fastscapelib flow routing): share of cells draining > 1 km2 and the
       drainage density of those channels (km/km2).
    7. Low ground: the slopes of the lowest :data:`LOW_GROUND_SHARE` of the cells by elevation (a
       mountain range's lowest ground is its gorges; a flat basin at the base level is not).
    NaN cells are left out of every distribution.
    """
    z = np.asarray(dem.values, dtype=np.float64)
    if z.ndim != 2:
        raise InputError(f"landform statistics need a 2-D DEM; got shape {z.shape}")
    ok = np.isfinite(z)
    if ok.sum() < 4:
        raise InputError("landform statistics need a DEM with valid cells; this one is (almost) all nodata")
    dxr, dy = row_cell_sizes_m(dem)
    dxr = np.asarray(dxr, dtype=np.float64)
    dx = float(np.mean(dxr))
    gx, gy = _gradient(z, dxr, float(dy))
    slope = np.degrees(np.arctan(np.hypot(gx, gy)))
    rel = [_relief(z, _window_cells(w, dx, float(dy))) for w in relief_windows_m]
    zmin, zmax = float(np.nanmin(z)), float(np.nanmax(z))
    hyps = (z - zmin) / (zmax - zmin) if zmax > zmin else np.zeros_like(z)
    lap = laplacian(z, dxr, float(dy)) * 1000.0
    dshare, ddens = _drainage(z, dx, float(dy))
    return LandformStatistics(
        cell_size_m=float(math.sqrt(dx * float(dy))),
        shape=(int(z.shape[0]), int(z.shape[1])),
        slope_deg=_quantiles(slope),
        relief_1km=_quantiles(rel[0]),
        relief_5km=_quantiles(rel[1]),
        hypsometry=_quantiles(hyps),
        curvature_per_km=_quantiles(lap),
        flat_share=float(np.mean(slope[np.isfinite(slope)] < FLAT_SLOPE_DEG)),
        spectral_slope=spectral_slope(z, (dx, float(dy))),
        drainage_share=dshare,
        drainage_density=ddens,
        relief_window_m=(float(relief_windows_m[0]), float(relief_windows_m[1])),
        low_slope_deg=_quantiles(_low_ground(z, slope)),
    )


