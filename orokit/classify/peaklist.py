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

import json
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


def _read_numeric(path: Path, ncols: int, what: str) -> pd.DataFrame:
    try:
        df = pd.read_csv(path, header=None, comment="#", sep=",", skipinitialspace=True)
        if df.shape[1] == 1:
            df = pd.read_csv(path, header=None, comment="#", sep=r"\s+")
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot parse {what} file {path}: {exc}") from exc
    if df.shape[1] < ncols:
        raise InputError(f"{what} file {path} has {df.shape[1]} columns per line, expected {ncols} "
                         f"(Kirmse & de Ferranti layout)")
    df = df.iloc[:, :ncols]
    num = df.apply(pd.to_numeric, errors="coerce")
    bad = num.isna().any(axis=1)
    if bad.iloc[:1].all() and len(df) > 1:  # a header line
        num, bad = num.iloc[1:], bad.iloc[1:]
    if bad.any():
        i = int(np.flatnonzero(bad.to_numpy())[0])
        raise InputError(f"{what} file {path}: line {i + 1} is not numeric: {df.iloc[i].tolist()}")
    return num.astype(float).reset_index(drop=True)


def read_kirmse_peaks(prominence_path: PathLike, isolation_path: PathLike | None = None, *,
                      z_units: str = "ft", missing_isolation_m: float | None = 500.0) -> gpd.GeoDataFrame:
    """Read Kirmse & de Ferranti prominence (and isolation) lists into a normalized table.

    Parameters
    ----------
    prominence_path : path
        ``lat,lon,elevation,saddle_lat,saddle_lon,prominence`` per line.
    isolation_path : path, optional
        ``lat,lon,elevation,ilp_lat,ilp_lon,isolation_km`` per line; joined to the
        prominence list on the peak position (rounded to 1e-5 degree).
    z_units : {"ft", "m"}
        Units of elevation and prominence in the files (the published lists use feet).
    missing_isolation_m : float or None
        Isolation given to peaks missing from the isolation list (None: unknown,
        which the features count as >= R). Without an isolation file every isolation
        is unknown and a warning is issued.

    Returns
    -------
    GeoDataFrame
        Normalized peak table in EPSG:4326.
    """
    if z_units not in _UNITS:
        raise UnitsError(f"z_units must be one of {sorted(_UNITS)}, got {z_units!r}")
    f = _UNITS[z_units]
    prom = _read_numeric(Path(prominence_path), 6, "prominence")
    prom.columns = ["lat", "lon", "elevation", "saddle_lat", "saddle_lon", "prominence"]
    lat_ok = prom["lat"].between(-90, 90) & prom["saddle_lat"].between(-90, 90)
    if not lat_ok.all():
        raise InputError(f"{prominence_path}: latitudes outside [-90, 90] (first bad line "
                         f"{int(np.flatnonzero(~lat_ok.to_numpy())[0]) + 1}); is the column order lat,lon,...?")
    peaks = pd.DataFrame({
        "x": prom["lon"], "y": prom["lat"], "elevation": prom["elevation"] * f,
        "prominence": prom["prominence"] * f, "saddle_x": prom["saddle_lon"], "saddle_y": prom["saddle_lat"],
    })
    # the highest peak of a landmass has no key saddle; Kirmse writes the peak itself or zeros
    nosad = ((peaks["saddle_x"] == peaks["x"]) & (peaks["saddle_y"] == peaks["y"])) | (
        (peaks["saddle_x"] == 0) & (peaks["saddle_y"] == 0))
    peaks.loc[nosad, ["saddle_x", "saddle_y"]] = np.nan
    if isolation_path is not None:
        iso = _read_numeric(Path(isolation_path), 6, "isolation")
        iso.columns = ["lat", "lon", "elevation", "ilp_lat", "ilp_lon", "isolation_km"]
        key = lambda a, b: list(zip(np.round(a.to_numpy(), 5), np.round(b.to_numpy(), 5)))  # noqa: E731
        table = pd.DataFrame({"ilp_lon": iso["ilp_lon"].to_numpy(), "ilp_lat": iso["ilp_lat"].to_numpy(),
                              "iso": iso["isolation_km"].to_numpy() * 1000.0},
                             index=pd.MultiIndex.from_tuples(key(iso["lat"], iso["lon"])))
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
        warnings.warn(f"no isolation list given with {prominence_path}: isolation features will count every "
                      f"peak as isolated beyond R; pass the isolation file (CLI: --isolation)", OrokitWarning,
                      stacklevel=2)
    out = peak_geometry(peaks, crs="EPSG:4326")
    out.attrs.update({"source": str(prominence_path), "format": "kirmse", "z_units_in": z_units})
    return out


def _looks_like_kirmse(path: Path) -> bool:
    with open(path, encoding="utf-8", errors="replace") as fh:
        for line in fh:
            s = line.strip()
            if not s or s.startswith("#"):
                continue
            parts = [p for p in s.replace(",", " ").split() if p]
            try:
                [float(p) for p in parts]
            except ValueError:
                return False
            return len(parts) >= 6
    return False


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
    p = Path(source)
    if not p.exists():
        raise InputError(f"peak list {p} does not exist")
    attrs: dict[str, Any] = {"source": str(p)}
    if p.is_dir():
        if not (p / "peaks.parquet").exists():
            raise InputError(f"{p} is a folder without peaks.parquet; pass an `orokit analyze` output folder")
        if (p / "analysis.json").exists():
            attrs["analysis"] = json.loads((p / "analysis.json").read_text())
        p = p / "peaks.parquet"
    suffix = p.suffix.lower()
    if suffix == ".parquet":
        try:
            df = gpd.read_parquet(p)
        except (ValueError, KeyError):
            df = pd.read_parquet(p)
    elif suffix in (".gpkg", ".shp", ".geojson", ".fgb"):
        import pyogrio

        layers = [name for name, _ in pyogrio.list_layers(p)]
        df = gpd.read_file(p, layer="peaks" if "peaks" in layers else layers[0])
    elif suffix in (".csv", ".txt", ".tsv", ".xyz") or suffix == "":
        if _looks_like_kirmse(p):
            out = read_kirmse_peaks(p, isolation, z_units=z_units or "ft")
            return out
        df = pd.read_csv(p)
    else:
        raise InputError(f"unsupported peak list format {p.suffix!r} ({p}); use .parquet, .gpkg, .csv or a "
                         f"Kirmse .txt list")
    if z_units not in (None, "m"):
        raise UnitsError(f"orokit peak tables are in metres; got z_units={z_units!r} for {p}")
    out = peak_geometry(df, crs=crs)
    out.attrs.update(attrs)
    return out
