"""Peak-list readers: every list :command:`orokit compare` accepts, and orokit tables.

:func:`read_peak_list`:

An orokit analysis folder (or its ``peaks.parquet`` / ``peaks.csv``), a Divide Tree
(``.gpkg``, reference ``.txt``, Kirmse ``.dvt``: prominences and parents from the tree
itself) or a Kirmse peak list (``results.txt`` or ``compute_parents`` output). Every
table comes out with the same columns: ``lat``, ``lon``, ``row``, ``col``, ``x``,
``y`` (NaN when the source has none), ``elevation``, ``prominence`` (metres, or the
file's units for Kirmse lists) and ``line_parent``, ``prominence_parent`` (row
positions in the same table, -1 for none or unknown).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from orokit._typing import PathLike
from orokit.errors import InputError
from orokit.io.kirmse_io import is_kirmse_list, read_kirmse_peaks

__all__ = ["PEAK_LIST_COLUMNS", "read_peak_list", "read_peak_table"]

PEAK_LIST_COLUMNS = ["lat", "lon", "row", "col", "x", "y", "elevation", "prominence", "line_parent",
                     "prominence_parent"]


def _frame(**cols) -> pd.DataFrame:
    n = len(cols["elevation"])
    out = {}
    for c in PEAK_LIST_COLUMNS:
        v = cols.get(c)
        if v is None:
            v = np.full(n, -1 if c.endswith("parent") else np.nan)
        out[c] = np.asarray(v, dtype=np.int64 if c.endswith("parent") else np.float64)
    return pd.DataFrame(out)


def _from_tree(tree) -> pd.DataFrame:
    table = tree.prominence_table()
    par = tree.parents(table)
    pk = tree.peaks
    get = lambda c: pk[c].to_numpy(float) if c in pk.columns else None  # noqa: E731
    return _frame(lat=get("lat"), lon=get("lon"), row=get("row"), col=get("col"), x=get("x"), y=get("y"),
                  elevation=get("elevation"), prominence=table["prominence"].to_numpy(),
                  line_parent=par["line_parent"].to_numpy(), prominence_parent=par["prominence_parent"].to_numpy())


def _kirmse_parent_ids(frame: pd.DataFrame, lat: np.ndarray, lon: np.ndarray) -> np.ndarray:
    """Rows of ``frame`` at the parents' (lat, lon) (compute_parents writes 4 decimals)."""
    from scipy.spatial import cKDTree

    out = np.full(lat.size, -1, np.int64)
    ok = np.isfinite(lat) & ~((lat == 0) & (lon == 0))
    if ok.any() and len(frame):
        d, i = cKDTree(frame[["lat", "lon"]].to_numpy()).query(np.column_stack([lat[ok], lon[ok]]))
        out[np.flatnonzero(ok)[d <= 1e-4]] = i[d <= 1e-4]
    return out


def read_peak_list(path: PathLike, *, cell_size_m: float | None = None, z_units: str = "ft",
                   height: int | None = None) -> pd.DataFrame:
    """Peak table of ``path`` with :data:`PEAK_LIST_COLUMNS` (see the module doc).

    ``cell_size_m``, ``z_units`` and ``height`` (rows of the DEM, which gives raster
    rows) apply to reference ``.txt`` Divide Trees only.
    """
    p = Path(path)
    if not p.exists():
        raise InputError(f"{p} does not exist: pass an analysis folder, a peaks table, a Divide Tree "
                         "(.gpkg, .txt, .dvt) or a Kirmse peak list (results.txt)")
    suffix = p.suffix.lower()
    if p.is_dir() or suffix in (".parquet", ".csv"):
        from orokit.io.analysis_io import read_peaks

        if p.is_dir() and not (p / "peaks.parquet").exists() and (p / "dividetree.gpkg").exists():
            from orokit.io.divide_tree_io import read_divide_tree

            return _from_tree(read_divide_tree(p))
        t = read_peaks(p)
        missing = [c for c in ("elevation", "prominence") if c not in t.columns]
        if missing:
            raise InputError(f"{p} has no {' or '.join(missing)} column: a peak list needs both; pass an `orokit "
                             "analyze` output folder or its peaks table")
        get = lambda c: t[c].to_numpy() if c in t.columns else None  # noqa: E731
        try:
            return _frame(lat=get("lat"), lon=get("lon"), row=get("row"), col=get("col"), x=get("x"), y=get("y"),
                          elevation=get("elevation"), prominence=get("prominence"), line_parent=get("line_parent"),
                          prominence_parent=get("prominence_parent"))
        except (ValueError, TypeError) as exc:
            raise InputError(f"{p}: a column of the peak list is not numeric ({exc}); pass an `orokit analyze` "
                             "output folder or its peaks table") from None
    if suffix == ".dvt":
        from orokit.io.kirmse_io import read_kirmse_tree

        tree = read_kirmse_tree(p)
        frame = _from_tree(tree)
        frame["row"], frame["col"] = frame["y"], frame["x"]  # sample offsets, y southwards
        return frame
    if suffix == ".txt" and is_kirmse_list(p):

        k = read_kirmse_peaks(p)
        frame = _frame(lat=k["lat"], lon=k["lon"], elevation=k["elevation"], prominence=k["prominence"])
        if "line_parent_lat" in k.columns:
            frame["line_parent"] = _kirmse_parent_ids(frame, k["line_parent_lat"].to_numpy(),
                                                      k["line_parent_lon"].to_numpy())
            frame["prominence_parent"] = _kirmse_parent_ids(frame, k["prominence_parent_lat"].to_numpy(),
                                                            k["prominence_parent_lon"].to_numpy())
        return frame
    if suffix == ".txt":
        from orokit.io.divide_tree_txt import read_divide_tree_txt

        return _from_tree(read_divide_tree_txt(p, cell_size_m=cell_size_m, z_units=z_units, height=height))
    if suffix == ".gpkg":
        from orokit.io.divide_tree_io import read_divide_tree

        return _from_tree(read_divide_tree(p, cell_size_m=cell_size_m, z_units=z_units))
    raise InputError(f"{p}: unknown peak list format {suffix or '(no suffix)'!r}; expected an analysis folder, "
                     "peaks.parquet/.csv, a Divide Tree (.gpkg, .txt, .dvt) or a Kirmse results.txt")


def read_peak_table(source: PathLike) -> pd.DataFrame:
    """An orokit peaks table as stored: analysis folder, ``.parquet``, ``.gpkg`` (layer
    ``peaks``) / other vector file, or ``.csv`` with a header.

    ``attrs["source"]`` names the file; an analysis folder adds ``attrs["analysis"]``
    (its ``analysis.json``). Kirmse lists are read by :mod:`orokit.io.kirmse_io`.
    """
    import json

    import geopandas as gpd

    p = Path(source)
    if not p.exists():
        raise InputError(f"peak list {p} does not exist")
    attrs: dict = {"source": str(p)}
    if p.is_dir():
        if not (p / "peaks.parquet").exists():
            raise InputError(f"{p} is a folder without peaks.parquet; pass an `orokit analyze` output folder")
        if (p / "analysis.json").exists():
            attrs["analysis"] = json.loads((p / "analysis.json").read_text())
        p = p / "peaks.parquet"
    suffix = p.suffix.lower()
    df: pd.DataFrame
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
        df = pd.read_csv(p)
    else:
        raise InputError(f"unsupported peak list format {p.suffix!r} ({p}); use .parquet, .gpkg, .csv or a "
                         f"Kirmse .txt list")
    df.attrs.update(attrs)
    return df
