"""Peak lists for classification: orokit peak tables and Kirmse & de Ferranti lists.

Every reader returns a *normalized* peak table (GeoDataFrame, metres, CRS set when
known) with the columns of :data:`NORMALIZED_COLUMNS`, which is what
:func:`orokit.classify.features.feature_table` consumes:

``x, y`` (CRS coordinates: lon/lat degrees for geographic CRS), ``elevation`` and
``prominence`` (m), ``saddle_distance_m`` and ``saddle_direction_deg`` (peak -> key
saddle), ``isolation_m`` and ``isolation_direction_deg`` (peak -> isolation target),
``prominence_exact`` (bool).

Distances and directions are geodesic (``pyproj.Geod``, WGS84) for geographic CRS and
Euclidean otherwise. Directions are degrees counter-clockwise from east in [0, 360).

Kirmse & de Ferranti world lists (github.com/akirmse/mountains, "Results"):

- prominence file, one peak per line:
  ``latitude,longitude,elevation_ft,key_saddle_latitude,key_saddle_longitude,prominence_ft``
- isolation file, one peak per line:
  ``latitude,longitude,elevation_ft,ILP_latitude,ILP_longitude,isolation_km``

The isolation list only holds peaks with isolation >= 1 km; a peak of the prominence
list that is missing from it gets ``missing_isolation_m`` (default 500 m, the middle of
[0, 1 km)) and no isolation direction.
"""
from __future__ import annotations

import logging
import warnings
from pathlib import Path
from typing import Any

import geopandas as gpd
import numpy as np
import pandas as pd
from numpy.typing import NDArray

from orokit._typing import PathLike
from orokit.errors import InputError, OrokitWarning, SchemaError, UnitsError
from orokit.geodesy import parse_crs, point_distance

logger = logging.getLogger(__name__)

FT = 0.3048
NORMALIZED_COLUMNS = [
    "x", "y", "elevation", "prominence", "saddle_distance_m", "saddle_direction_deg",
    "isolation_m", "isolation_direction_deg", "prominence_exact",
]
_UNITS = {"m": 1.0, "ft": FT}


def is_geographic(crs: Any) -> bool:
    """True for a geographic (lon/lat degrees) CRS."""
    c = parse_crs(crs)
    return bool(c is not None and c.is_geographic)


def peak_geometry(peaks: pd.DataFrame, *, crs: Any = None) -> gpd.GeoDataFrame:
    """Normalize an orokit peak table (contract columns) for classification.

    Parameters
    ----------
    peaks : DataFrame or GeoDataFrame
        Columns x, y, elevation, prominence and, when available, saddle_x, saddle_y,
        isolation (m), isolation_x, isolation_y, prominence_exact.
    crs : CRS-like, optional
        Overrides ``peaks.crs``.

    Returns
    -------
    GeoDataFrame
        :data:`NORMALIZED_COLUMNS` plus Point geometry; the input index is kept.
    """
    crs = parse_crs(crs if crs is not None else getattr(peaks, "crs", None))
    need = ["x", "y", "elevation", "prominence"]
    missing = [c for c in need if c not in peaks]
    if missing:
        raise SchemaError(f"peak table lacks columns {missing}; expected the orokit peaks table "
                          f"(x, y, elevation, prominence, saddle_x, saddle_y, isolation, ...)")
    x = peaks["x"].to_numpy(dtype=float)
    y = peaks["y"].to_numpy(dtype=float)
    nan = np.full(len(peaks), np.nan)
    sx = peaks["saddle_x"].to_numpy(dtype=float) if "saddle_x" in peaks else nan
    sy = peaks["saddle_y"].to_numpy(dtype=float) if "saddle_y" in peaks else nan
    sd, sa = point_distance(x, y, sx, sy, crs=crs)
    ix = peaks["isolation_x"].to_numpy(dtype=float) if "isolation_x" in peaks else nan
    iy = peaks["isolation_y"].to_numpy(dtype=float) if "isolation_y" in peaks else nan
    idist, ia = point_distance(x, y, ix, iy, crs=crs)
    iso = peaks["isolation"].to_numpy(dtype=float) if "isolation" in peaks else idist
    exact = (peaks["prominence_exact"].to_numpy(dtype=bool) if "prominence_exact" in peaks
             else np.ones(len(peaks), dtype=bool))
    out = pd.DataFrame({
        "x": x, "y": y,
        "elevation": peaks["elevation"].to_numpy(dtype=float),
        "prominence": peaks["prominence"].to_numpy(dtype=float),
        "saddle_distance_m": sd, "saddle_direction_deg": sa,
        "isolation_m": iso, "isolation_direction_deg": ia,
        "prominence_exact": exact,
    }, index=peaks.index)
    return gpd.GeoDataFrame(out, geometry=gpd.points_from_xy(x, y), crs=crs)


def normalize_kirmse(prominence: pd.DataFrame, isolation: pd.DataFrame | None = None, *, z_units: str = "ft",
                     missing_isolation_m: float | None = 500.0, source: str = "") -> gpd.GeoDataFrame:
    """Normalized peak table of Kirmse & de Ferranti lists as read by :mod:`orokit.io.kirmse_io`.

    Parameters
    ----------
    prominence : DataFrame
        ``read_kirmse_peaks`` output (lat, lon, elevation, saddle_lat, saddle_lon, prominence).
    isolation : DataFrame, optional
        ``read_kirmse_isolation`` output, joined on the peak position (rounded to 1e-5 degree).
    z_units : {"ft", "m"}
        Units of elevation and prominence in the lists (the published lists use feet).
    missing_isolation_m : float or None
        Isolation given to peaks missing from the isolation list (None: unknown, which the
        features count as >= R). Without an isolation list every isolation is unknown and a
        warning is issued.
    source : str
        Name of the prominence list, for messages and ``attrs``.
    """
    if z_units not in _UNITS:
        raise UnitsError(f"z_units must be one of {sorted(_UNITS)}, got {z_units!r}")
    f = _UNITS[z_units]
    peaks = pd.DataFrame({
        "x": prominence["lon"].to_numpy(float), "y": prominence["lat"].to_numpy(float),
        "elevation": prominence["elevation"].to_numpy(float) * f,
        "prominence": prominence["prominence"].to_numpy(float) * f,
        "saddle_x": prominence["saddle_lon"].to_numpy(float), "saddle_y": prominence["saddle_lat"].to_numpy(float),
    })
    if isolation is not None:
        key = lambda a, b: list(zip(np.round(a.to_numpy(), 5), np.round(b.to_numpy(), 5)))  # noqa: E731
        table = pd.DataFrame({"ilp_lon": isolation["ilp_lon"].to_numpy(), "ilp_lat": isolation["ilp_lat"].to_numpy(),
                              "iso": isolation["isolation_km"].to_numpy() * 1000.0},
                             index=pd.MultiIndex.from_tuples(key(isolation["lat"], isolation["lon"])))
        table = table[~table.index.duplicated()]
        joined = table.reindex(pd.MultiIndex.from_tuples(key(peaks["y"], peaks["x"])))
        peaks["isolation_x"] = joined["ilp_lon"].to_numpy()
        peaks["isolation_y"] = joined["ilp_lat"].to_numpy()
        isol = joined["iso"].to_numpy()
        n_missing = int(np.isnan(isol).sum())
        if missing_isolation_m is not None:
            isol = np.where(np.isnan(isol), float(missing_isolation_m), isol)
        peaks["isolation"] = isol
        logger.info("isolation list: %d of %d peaks matched", len(peaks) - n_missing, len(peaks))
    else:
        warnings.warn(f"no isolation list given with {source or 'the prominence list'}: isolation features will "
                      f"count every peak as isolated beyond R; pass the isolation file (CLI: --isolation)",
                      OrokitWarning, stacklevel=3)
    out = peak_geometry(peaks, crs="EPSG:4326")
    out.attrs.update({"source": source, "format": "kirmse", "z_units_in": z_units})
    return out


def read_kirmse_peaks(prominence_path: PathLike, isolation_path: PathLike | None = None, *,
                      z_units: str = "ft", missing_isolation_m: float | None = 500.0) -> gpd.GeoDataFrame:
    """Read Kirmse & de Ferranti prominence (and isolation) lists into a normalized table
    (EPSG:4326); see :func:`normalize_kirmse` for the parameters."""
    from orokit.io.kirmse_io import read_kirmse_isolation
    from orokit.io.kirmse_io import read_kirmse_peaks as read_list

    if z_units not in _UNITS:
        raise UnitsError(f"z_units must be one of {sorted(_UNITS)}, got {z_units!r}")
    prom = read_list(prominence_path)
    iso = read_kirmse_isolation(isolation_path) if isolation_path is not None else None
    return normalize_kirmse(prom, iso, z_units=z_units, missing_isolation_m=missing_isolation_m,
                            source=str(prominence_path))


def read_peaks(source: PathLike, *, crs: Any = None, z_units: str | None = None,
               isolation: PathLike | None = None) -> gpd.GeoDataFrame:
    """Read any supported peak list and return a normalized peak table.

    Parameters
    ----------
    source : path
        An ``orokit analyze`` output folder (``peaks.parquet``), an orokit peaks table
        (``.parquet``, ``.gpkg`` layer ``peaks``, ``.csv`` with a header), or a Kirmse &
        de Ferranti prominence list (``.txt``/``.csv`` without header).
    crs : CRS-like, optional
        CRS of a CSV table (GeoParquet/GeoPackage carry their own).
    z_units : {"m", "ft"}, optional
        Units of Kirmse lists (default ft); orokit tables are always metres.
    isolation : path, optional
        Kirmse isolation list to join to a Kirmse prominence list.
    """
    from orokit.io.kirmse_io import is_kirmse_list
    from orokit.io.peak_lists import read_peak_table

    p = Path(source)
    if not p.exists():
        raise InputError(f"peak list {p} does not exist")
    if p.is_file() and p.suffix.lower() in (".csv", ".txt", ".tsv", ".xyz", "") and is_kirmse_list(p):
        return read_kirmse_peaks(p, isolation, z_units=z_units or "ft")
    df = read_peak_table(p)
    if z_units not in (None, "m"):
        raise UnitsError(f"orokit peak tables are in metres; got z_units={z_units!r} for {p}")
    out = peak_geometry(df, crs=crs)
    out.attrs.update(df.attrs)
    return out
