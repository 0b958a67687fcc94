"""Distances and directions between raster cells or points, in metres and degrees.

One helper for the whole toolkit, so that geographic grids (cells that are not square
on the ground) and projected or local metric grids are measured the same way:

- geographic CRS: geodesics on the WGS84 ellipsoid (:class:`pyproj.Geod`, Karney);
- projected CRS: Euclidean distance in the CRS, converted to metres with the CRS's
  linear unit (feet-based state planes work);
- no CRS (local metric grid from :func:`orokit.io.dem.read_dem`): Euclidean, metres.

Directions are degrees counter-clockwise from east in ``[0, 360)`` (east = 0,
north = 90), the convention of the orometric features (DESIGN.md section 3). For
geodesics the direction is the forward azimuth at the first point.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pyproj import CRS, Geod, Transformer
from rasterio.transform import Affine

from orokit.errors import CRSError

if TYPE_CHECKING:  # pragma: no cover
    import xarray as xr

__all__ = ["CellMetric", "cell_distance", "point_distance", "parse_crs", "metric_crs", "linear_unit_m", "cell_size_key",
           "cell_size_attrs", "WGS84"]

#: The ellipsoid used for every geodesic computation in orokit.
WGS84 = Geod(ellps="WGS84")
_EPSG4326 = CRS.from_epsg(4326)


def cell_size_key(geographic: bool) -> str:
    """Attrs key of a grid's cell size (dx, dy): ``cell_size_deg`` on lon/lat grids, else ``cell_size_m``."""
    return "cell_size_deg" if geographic else "cell_size_m"


def cell_size_attrs(transform: Affine, crs: Any) -> dict[str, tuple[float, float]]:
    """A grid's cell size (dx, dy) under its attrs key (:func:`cell_size_key`): degrees on lon/lat grids,
    else metres (a projected CRS's feet converted).

    >>> cell_size_attrs(Affine(30, 0, 0, 0, -30, 0), "EPSG:32633"), cell_size_attrs(Affine(100, 0, 0, 0, -100, 0), "EPSG:2227")
    ({'cell_size_m': (30.0, 30.0)}, {'cell_size_m': (30.480060960121925, 30.480060960121925)})
    """
    c = parse_crs(crs)
    geographic = c is not None and c.is_geographic
    unit = 1.0 if geographic else linear_unit_m(c)
    return {cell_size_key(geographic): (float(abs(transform.a)) * unit, float(abs(transform.e)) * unit)}


@functools.lru_cache(maxsize=32)
def _to_lonlat(crs_wkt: str) -> Transformer:
    return Transformer.from_crs(CRS.from_wkt(crs_wkt), _EPSG4326, always_xy=True)


def parse_crs(crs: Any) -> CRS | None:
    """A :class:`pyproj.CRS` from any CRS-like input (EPSG code, "EPSG:xxxx", WKT, CRS), None for None.

    Raises
    ------
    CRSError
        pyproj cannot interpret ``crs``; the message names the value and the fix.

    Examples
    --------
    >>> parse_crs("EPSG:4326").is_geographic, parse_crs(None)
    (True, None)
    """
    if crs is None:
        return None
    try:
        return CRS.from_user_input(crs)
    except Exception as exc:  # pyproj raises CRSError subclasses of its own
        raise CRSError(f"cannot interpret CRS {crs!r}: {exc}. Pass an EPSG code or WKT, e.g. 'EPSG:32633'.") from exc


def metric_crs(crs: Any, what: str) -> CRS | None:
    """``crs`` (None: a local metric frame) when its coordinates are metres; ``what`` (e.g. "the Divide
    Tree") names the data in the message.

    Raises
    ------
    CRSError
        A geographic CRS, or a projected one in other units (US survey feet: a tree analysed from such a
        DEM), whose coordinates would be taken for metres.

    Examples
    --------
    >>> metric_crs("EPSG:32633", "the tree").name, metric_crs(None, "the tree")
    ('WGS 84 / UTM zone 33N', None)
    >>> metric_crs("EPSG:2227", "the tree")
    Traceback (most recent call last):
    ...
    orokit.errors.CRSError: the tree is in the CRS 'NAD83 / California zone 3 (ftUS)', whose unit is the US survey foot (0.3048006 m); this needs metres: reproject it, or the DEM it came from (gdalwarp -t_srs), to a metric CRS (e.g. its UTM zone) first
    """
    c = parse_crs(crs)
    if c is None:
        return None
    if c.is_geographic:
        raise CRSError(f"{what} is in a geographic CRS ({c.name}); this needs metres: reproject it to a projected "
                       "CRS (e.g. its UTM zone) first")
    unit_m = linear_unit_m(c)
    if unit_m != 1.0:
        unit = c.axis_info[0].unit_name
        raise CRSError(f"{what} is in the CRS {c.name!r}, whose unit is the {unit} ({unit_m:.7g} m); this needs "
                       "metres: reproject it, or the DEM it came from (gdalwarp -t_srs), to a metric CRS (e.g. its "
                       "UTM zone) first")
    return c


def linear_unit_m(crs: CRS | None) -> float:
    """Metres per unit of a projected CRS's coordinates (1.0 for none or a geographic one).

    >>> round(linear_unit_m(CRS.from_epsg(2227)), 7), linear_unit_m(CRS.from_epsg(32633))
    (0.3048006, 1.0)
    """
    if crs is None or crs.is_geographic:
        return 1.0
    factors = {ax.unit_conversion_factor for ax in crs.axis_info[:2] if ax.unit_conversion_factor}
    if not factors:
        return 1.0
    if len(factors) > 1:  # pragma: no cover - exotic
        raise CRSError(f"CRS {crs.name!r} has different units on its two axes; reproject to a metric CRS first.")
    return float(factors.pop())


def _ccw_from_east(azimuth_cw_from_north: NDArray[np.float64]) -> NDArray[np.float64]:
    a = np.mod(90.0 - azimuth_cw_from_north, 360.0)
    return np.where(a >= 360.0, 0.0, a)  # np.mod(-1e-17, 360) == 360.0


@dataclass(frozen=True)
class CellMetric:
    """Measure distances (metres) and directions (degrees CCW from east) on a grid.

    Parameters
    ----------
    transform
        Affine transform of the grid (pixel corner -> CRS coordinates), as from
        ``dem.rio.transform()``.
    crs
        CRS of the grid, or None for a local metric grid.

    Notes
    -----
    Row/column indices are 0-based; a cell is represented by its centre. All methods
    are vectorised: arguments broadcast like numpy arrays.

    Examples
    --------
    >>> m = CellMetric(Affine(30, 0, 0, 0, -30, 300), "EPSG:32633")
    >>> float(m.distance(0, 0, 3, 4)), float(m.direction(0, 0, 0, 1)), float(m.direction(1, 0, 0, 0))
    (150.0, 0.0, 90.0)
    """

    transform: Affine
    crs: CRS | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "crs", parse_crs(self.crs))
        object.__setattr__(self, "transform", Affine(*tuple(self.transform)[:6]))

    # -- construction -------------------------------------------------------------
    @classmethod
    def from_dem(cls, dem: xr.DataArray) -> CellMetric:
        """Build the metric of a DEM read by :func:`orokit.io.dem.read_dem` (or any
        rioxarray-georeferenced DataArray with dims ``("y", "x")``)."""
        try:
            transform = dem.rio.transform()
            crs = dem.rio.crs
        except Exception as exc:
            raise CRSError(f"DEM has no usable transform: {exc}. Read it with orokit.io.read_dem.") from exc
        return cls(transform, crs)

    # -- properties ---------------------------------------------------------------
    @property
    def is_geographic(self) -> bool:
        """True when coordinates are longitude/latitude degrees."""
        return bool(self.crs is not None and self.crs.is_geographic)

    @functools.cached_property
    def _is_wgs84(self) -> bool:
        return bool(self.crs is not None and self.crs.equals(_EPSG4326))

    @property
    def unit_m(self) -> float:
        """Metres per CRS unit (1 for metric and local grids; not used for geographic)."""
        return linear_unit_m(self.crs)

    # -- coordinates --------------------------------------------------------------
    def xy(self, rows: ArrayLike, cols: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """CRS coordinates of cell centres."""
        r = np.asarray(rows, dtype=np.float64) + 0.5
        c = np.asarray(cols, dtype=np.float64) + 0.5
        t = self.transform
        return t.a * c + t.b * r + t.c, t.d * c + t.e * r + t.f

    def lonlat(self, x: ArrayLike, y: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Longitude/latitude (WGS84 degrees) of CRS points; NaN when there is no CRS."""
        xa, ya = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
        if self.crs is None:
            nan = np.full(xa.shape, np.nan)
            return nan, nan.copy()
        if self._is_wgs84:
            return xa.copy(), ya.copy()
        lon, lat = _to_lonlat(self.crs.to_wkt()).transform(xa, ya)
        return np.asarray(lon, dtype=np.float64), np.asarray(lat, dtype=np.float64)

    def _geodetic(self, x: NDArray[np.float64], y: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        if self._is_wgs84:
            return x, y
        return self.lonlat(x, y)

    # -- distances ----------------------------------------------------------------
    def point_distance_direction(
        self, x0: ArrayLike, y0: ArrayLike, x1: ArrayLike, y1: ArrayLike
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Distance (m) and direction (degrees CCW from east, [0, 360)) between CRS points.

        NaN where either end has a NaN coordinate; the direction is NaN between
        identical points.
        """
        x0a, y0a, x1a, y1a = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (x0, y0, x1, y1)))
        ok = np.isfinite(x0a) & np.isfinite(y0a) & np.isfinite(x1a) & np.isfinite(y1a)
        dist = np.full(x0a.shape, np.nan)
        direction = np.full(x0a.shape, np.nan)
        if not ok.any():
            return dist, direction
        x0a, y0a, x1a, y1a = x0a[ok], y0a[ok], x1a[ok], y1a[ok]
        if self.is_geographic:
            lon0, lat0 = self._geodetic(x0a, y0a)
            lon1, lat1 = self._geodetic(x1a, y1a)
            az, _, d = WGS84.inv(lon0, lat0, lon1, lat1)
            d = np.asarray(d, dtype=np.float64)
            a = _ccw_from_east(np.asarray(az, dtype=np.float64))
        else:
            dx = (x1a - x0a) * self.unit_m
            dy = (y1a - y0a) * self.unit_m
            d = np.hypot(dx, dy)
            a = np.mod(np.degrees(np.arctan2(dy, dx)), 360.0)
            a = np.where(a >= 360.0, 0.0, a)
        dist[ok] = d
        direction[ok] = np.where(d > 0, a, np.nan)  # identical points: direction undefined
        return dist, direction

    def distance_direction(
        self, row0: ArrayLike, col0: ArrayLike, row1: ArrayLike, col1: ArrayLike
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Distance (m) and direction (degrees CCW from east) from cells 0 to cells 1.

        The direction is NaN where both cells are the same.
        """
        x0, y0 = self.xy(row0, col0)
        x1, y1 = self.xy(row1, col1)
        return self.point_distance_direction(x0, y0, x1, y1)

    def distance(self, row0: ArrayLike, col0: ArrayLike, row1: ArrayLike, col1: ArrayLike) -> NDArray[np.float64]:
        """Distance in metres between cell centres."""
        return self.distance_direction(row0, col0, row1, col1)[0]

    def direction(self, row0: ArrayLike, col0: ArrayLike, row1: ArrayLike, col1: ArrayLike) -> NDArray[np.float64]:
        """Direction from cell 0 to cell 1, degrees counter-clockwise from east."""
        return self.distance_direction(row0, col0, row1, col1)[1]

    def cell_size_m(self, rows: ArrayLike | None = None) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Ground size (m) of cells along x (east-west) and y (north-south).

        For geographic grids the east-west size shrinks with latitude, so it is
        given per row (``rows`` default: every row 0..n is not known here, so pass
        the rows you need; default row 0). Projected/local grids return constants.
        """
        r = np.atleast_1d(np.asarray(0 if rows is None else rows, dtype=np.float64))
        if self.is_geographic:
            dx = self.distance(r, 0, r, 1)
            dy = self.distance(r, 0, r + 1, 0)
            return dx, dy
        t = self.transform
        u = self.unit_m
        return np.full(r.shape, math.hypot(t.a, t.d) * u), np.full(r.shape, math.hypot(t.b, t.e) * u)


def cell_distance(
    dem: xr.DataArray, row0: ArrayLike, col0: ArrayLike, row1: ArrayLike, col1: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Distance (m) and direction (degrees CCW from east) between cells of ``dem``.

    Shortcut for ``CellMetric.from_dem(dem).distance_direction(...)``; build the
    :class:`CellMetric` once when calling this in a loop.
    """
    return CellMetric.from_dem(dem).distance_direction(row0, col0, row1, col1)


def point_distance(
    x0: ArrayLike, y0: ArrayLike, x1: ArrayLike, y1: ArrayLike, *, crs: Any = None
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Distance (m) and direction (degrees CCW from east) between points of ``crs``."""
    return CellMetric(Affine.identity(), crs).point_distance_direction(x0, y0, x1, y1)
