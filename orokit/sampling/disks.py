"""Blue-noise placement of disk domains (Argudo et al. 2019, section 4.2).

Disk centres are a Poisson-disk (blue-noise) sample with a minimum centre separation
of ``separation * R`` (0.5 R in the paper), generated with
:class:`scipy.stats.qmc.PoissonDisk`, restricted to the places where a disk of radius R
fits entirely inside the data: the valid cells of a DEM, or a region polygon eroded by R.
At most ``max_disks`` centres are kept per region (a random subset, so coverage stays
uniform). Everything is deterministic for a given ``rng`` seed.
"""
from __future__ import annotations

import logging
import math
from typing import Any

import geopandas as gpd
import numpy as np
import pandas as pd
import shapely
from numpy.typing import NDArray
from scipy import ndimage
from scipy.stats import qmc

from orokit._typing import SeedLike
from orokit.errors import CRSError, InputError

logger = logging.getLogger(__name__)

#: upper bound on Poisson-disk points drawn in a bounding box before the spacing is raised
#: (SciPy's PoissonDisk takes ~0.4 ms per point; at most ``max_disks`` are kept anyway,
#: and a larger spacing still satisfies the minimum separation)
MAX_CANDIDATES = 2_000

DISK_COLUMNS = ["disk_id", "x", "y", "radius_m"]


def _poisson_disk(rng: np.random.Generator, radius: float) -> qmc.PoissonDisk:
    try:
        return qmc.PoissonDisk(2, radius=radius, rng=rng)
    except TypeError:  # SciPy < 1.15 spells it seed=
        return qmc.PoissonDisk(2, radius=radius, seed=rng)


def blue_noise_points(width: float, height: float, spacing: float, *, rng: SeedLike = None) -> NDArray[np.float64]:
    """Poisson-disk points in ``[0, width) x [0, height)`` with pairwise distance >= ``spacing``.

    The sample fills the box (maximal blue-noise set), generated in the unit square of
    side ``max(width, height)`` by :class:`scipy.stats.qmc.PoissonDisk` and cropped.
    If more than :data:`MAX_CANDIDATES` points would be needed, the spacing is raised
    (logged), which keeps the separation constraint.
    """
    rng = np.random.default_rng(rng)
    if not (width > 0 and height > 0 and spacing > 0):
        return np.zeros((0, 2))
    side = max(width, height)
    expected = width * height / (0.7 * spacing * spacing)
    if expected > MAX_CANDIDATES:
        new = spacing * math.sqrt(expected / MAX_CANDIDATES)
        logger.info("raising disk-centre spacing from %.0f to %.0f to bound the sample size", spacing, new)
        spacing = new
    r = spacing / side
    if r >= 1.0:
        pts = rng.random((1, 2)) * side
    else:
        pts = _poisson_disk(rng, r).fill_space() * side
    keep = (pts[:, 0] < width) & (pts[:, 1] < height)
    return pts[keep]


def _subset(points: NDArray[np.float64], max_disks: int | None, rng: np.random.Generator) -> NDArray[np.float64]:
    if max_disks is not None and len(points) > max_disks:
        idx = np.sort(rng.choice(len(points), size=max_disks, replace=False))
        points = points[idx]
    return points


def _frame(xy: NDArray[np.float64], radius_m: float, crs: Any) -> gpd.GeoDataFrame:
    df = pd.DataFrame({"disk_id": np.arange(len(xy), dtype=np.int64), "x": xy[:, 0] if len(xy) else [],
                       "y": xy[:, 1] if len(xy) else [], "radius_m": float(radius_m)})
    return gpd.GeoDataFrame(df, geometry=gpd.points_from_xy(df["x"], df["y"]), crs=crs)


def _check(radius_m: float, separation: float, max_disks: int | None) -> None:
    if not (np.isfinite(radius_m) and radius_m > 0):
        raise InputError(f"disk radius must be a positive number of metres, got {radius_m!r}")
    if not separation > 0:
        raise InputError(f"disk separation must be > 0 (fraction of R; the paper uses 0.5), got {separation!r}")
    if max_disks is not None and max_disks < 0:
        raise InputError(f"max_disks must be >= 0, got {max_disks!r}")


def local_metric_crs(lon: float, lat: float) -> Any:
    """Azimuthal equidistant CRS centred on (lon, lat): distances from the centre are exact."""
    from pyproj import CRS

    return CRS.from_proj4(f"+proj=aeqd +lat_0={lat:.8f} +lon_0={lon:.8f} +datum=WGS84 +units=m +no_defs")


def sample_disks_in_polygon(polygon: Any, *, radius_m: float, crs: Any = None, separation: float = 0.5,
                            max_disks: int | None = 100, rng: SeedLike = None) -> gpd.GeoDataFrame:
    """Disk centres inside ``polygon`` eroded by R (whole disks inside the polygon).

    Parameters
    ----------
    polygon : shapely Polygon or MultiPolygon
        Region outline in ``crs`` (invalid geometries are repaired with ``make_valid``).
    radius_m : float
        Disk radius R in metres, measured on the ground.
    crs : CRS-like, optional
        CRS of the polygon. Geographic CRS: the polygon is projected to an azimuthal
        equidistant projection centred on its centroid, sampled there and the centres
        are returned in ``crs`` (lon/lat). Projected or ``None``: coordinates are metres.
    separation : float
        Minimum centre distance as a fraction of R (paper: 0.5).
    max_disks : int or None
        Keep at most this many centres (random subset).
    rng : Generator, int or None
        Seed.

    Returns
    -------
    GeoDataFrame
        Columns disk_id, x, y, radius_m and Point geometry in ``crs``; empty when the
        eroded polygon is empty (region smaller than a disk).
    """
    _check(radius_m, separation, max_disks)
    rng = np.random.default_rng(rng)
    geom = shapely.make_valid(polygon)
    if geom.is_empty:
        return _frame(np.zeros((0, 2)), radius_m, crs)
    to_local = from_local = None
    from pyproj import CRS, Transformer

    pcrs = CRS.from_user_input(crs) if crs is not None else None
    if pcrs is not None and pcrs.is_geographic:
        c = geom.centroid
        local = local_metric_crs(c.x, c.y)
        to_local = Transformer.from_crs(pcrs, local, always_xy=True)
        from_local = Transformer.from_crs(local, pcrs, always_xy=True)
        x0, y0, x1, y1 = geom.bounds
        # densify so that straight edges in degrees stay edges after projection
        geom = shapely.segmentize(geom, max(x1 - x0, y1 - y0) / 256 or 1e-3)
        geom = shapely.transform(geom, lambda xy: np.column_stack(to_local.transform(xy[:, 0], xy[:, 1])))
    elif pcrs is not None and pcrs.axis_info and pcrs.axis_info[0].unit_name not in ("metre", "meter"):
        raise CRSError(f"polygon CRS has units {pcrs.axis_info[0].unit_name!r}; use a metric or geographic CRS")
    inner = geom.buffer(-radius_m)
    if inner.is_empty:
        logger.info("region smaller than a disk of radius %.0f m: no disk", radius_m)
        return _frame(np.zeros((0, 2)), radius_m, crs)
    x0, y0, x1, y1 = inner.bounds
    pts = blue_noise_points(max(x1 - x0, 1e-9), max(y1 - y0, 1e-9), separation * radius_m, rng=rng)
    pts = pts + [x0, y0]
    if len(pts):
        shapely.prepare(inner)
        pts = pts[shapely.contains_xy(inner, pts[:, 0], pts[:, 1])]
    pts = _subset(pts, max_disks, rng)
    if from_local is not None and len(pts):
        lon, lat = from_local.transform(pts[:, 0], pts[:, 1])
        pts = np.column_stack([lon, lat])
    return _frame(pts, radius_m, crs)


def cell_size_m(transform: Any, crs: Any, shape: tuple[int, int]) -> tuple[float, float]:
    """Ground size (dx, dy) in metres of one cell; geographic grids measured at the centre row
    (through :class:`orokit.geodesy.CellMetric`, like every distance in orokit)."""
    from orokit.geodesy import CellMetric

    dx, dy = CellMetric(transform, crs).cell_size_m([int(shape[0]) // 2])
    return float(dx[0]), float(dy[0])


def sample_disks_in_mask(valid: NDArray[np.bool_], *, transform: Any, radius_m: float, crs: Any = None,
                         separation: float = 0.5, max_disks: int | None = 100, rng: SeedLike = None
                         ) -> gpd.GeoDataFrame:
    """Disk centres on a raster such that every disk lies entirely on valid cells.

    Parameters
    ----------
    valid : 2-D bool array
        True on cells with data (row 0 at the top).
    transform : affine.Affine
        Grid transform (north-up, no rotation).
    radius_m : float
        Disk radius R in metres on the ground.
    crs : CRS-like, optional
        Raster CRS; geographic grids are converted to metres with the cell size at the
        centre of the raster (good to a fraction of a percent over tens of km).
    separation, max_disks, rng
        As in :func:`sample_disks_in_polygon`.

    Returns
    -------
    GeoDataFrame
        Centres in the raster CRS (columns disk_id, x, y, radius_m, row, col).

    Notes
    -----
    1. Distance of every cell to the nearest invalid cell or to the outside of the
       raster (Euclidean distance transform in metres, the raster padded by one
       invalid ring).
    2. A centre is allowed in a cell when that distance is >= R plus half a cell
       diagonal, so no invalid cell centre and no raster edge is within R of any point
       of the cell.
    3. Blue-noise points over the raster extent, kept in allowed cells.
    """
    _check(radius_m, separation, max_disks)
    rng = np.random.default_rng(rng)
    valid = np.asarray(valid, dtype=bool)
    if valid.ndim != 2:
        raise InputError(f"valid mask must be 2-D, got shape {valid.shape}")
    if getattr(transform, "b", 0) or getattr(transform, "d", 0):
        raise InputError("rotated raster transforms are not supported for disk sampling; warp the DEM first")
    nrows, ncols = valid.shape
    dx, dy = cell_size_m(transform, crs, valid.shape)
    padded = np.pad(valid, 1, constant_values=False)
    dist = ndimage.distance_transform_edt(padded, sampling=(dy, dx))[1:-1, 1:-1]
    # distance to the pad is measured to the pad cell centre: one half cell beyond the edge
    allowed = dist >= radius_m + 0.5 * math.hypot(dx, dy) + 0.5 * max(dx, dy)
    if not allowed.any():
        return _frame_rc(np.zeros((0, 2)), radius_m, crs, transform)
    pts = blue_noise_points(ncols * dx, nrows * dy, separation * radius_m, rng=rng)
    cols = np.floor(pts[:, 0] / dx).astype(int)
    rows = np.floor(pts[:, 1] / dy).astype(int)
    inside = (rows >= 0) & (rows < nrows) & (cols >= 0) & (cols < ncols)
    pts, rows, cols = pts[inside], rows[inside], cols[inside]
    pts = pts[allowed[rows, cols]]
    pts = _subset(pts, max_disks, rng)
    rc = np.column_stack([pts[:, 1] / dy, pts[:, 0] / dx])  # fractional (row, col) from the top-left corner
    return _frame_rc(rc, radius_m, crs, transform)


def _frame_rc(rc: NDArray[np.float64], radius_m: float, crs: Any, transform: Any) -> gpd.GeoDataFrame:
    if len(rc):
        t = transform
        xy = np.column_stack([t.a * rc[:, 1] + t.b * rc[:, 0] + t.c, t.d * rc[:, 1] + t.e * rc[:, 0] + t.f])
    else:
        xy = np.zeros((0, 2))
    out = _frame(xy, radius_m, crs)
    out["row"] = rc[:, 0] - 0.5 if len(rc) else []  # cell-centre convention: row r spans [r-0.5, r+0.5)
    out["col"] = rc[:, 1] - 0.5 if len(rc) else []
    return out
