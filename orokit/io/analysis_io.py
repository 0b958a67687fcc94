"""Files of an analysis: peaks.csv, peaks.parquet, saddles.parquet, dividetree.gpkg, analysis.json.

All files are written atomically (temp file + rename); ``analysis.json`` is written
last, so a folder with it is complete and a rerun after an interruption redoes the
whole set.
"""
from __future__ import annotations

import json
import logging
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from orokit._typing import PathLike
from orokit.errors import InputError
from orokit.io.atomic import atomic_path, staged_folder, write_text_atomic
from orokit.io.files import read_json_file
from orokit.topology.tables import (
    AnalysisResult,
    table_rows,
    upgrade_attrs,
    validate_peak_table,
    validate_saddle_table,
)

if TYPE_CHECKING:
    import pandas as pd

logger = logging.getLogger(__name__)

__all__ = ["write_analysis", "read_analysis", "read_analysis_meta", "read_peaks", "read_peak_cells", "analysis_json",
           "ANALYSIS_FILES"]

ANALYSIS_FILES = ("peaks.csv", "peaks.parquet", "saddles.parquet", "dividetree.gpkg", "analysis.json")


def write_analysis(result: AnalysisResult, outdir: PathLike, *, overwrite: bool = False) -> Path:
    """Write an :class:`~orokit.topology.tables.AnalysisResult` into ``outdir``.

    The folder is locked while it is written (another process writing it gets
    :class:`~orokit.errors.OutputError`). The files are written into a hidden folder
    beside ``outdir`` and moved in only when all are complete, ``analysis.json`` last, so
    a failure (disk full, Ctrl-C) keeps a previous analysis byte-identical.
    """
    out = Path(outdir)
    with staged_folder(out, marker="analysis.json", names=ANALYSIS_FILES) as stage:
        if (out / "analysis.json").exists() and not overwrite:
            raise InputError(f"{out} already holds an analysis; pass overwrite=True (CLI: --overwrite)")
        _write(result, stage)
    logger.info("wrote %s", out)
    return out


def analysis_json(result: AnalysisResult) -> str:
    """Metadata of a result as JSON text (written next to the tables)."""
    meta = dict(result.attrs)
    meta["crs"] = None if result.crs is None else result.crs.to_wkt()
    meta["n_peaks"] = int(len(result.peaks))
    meta["n_saddles"] = int(len(result.saddles))
    return json.dumps(meta, indent=2, default=str)


def _write(result: AnalysisResult, out: Path) -> Path:
    from concurrent.futures import ThreadPoolExecutor

    from orokit.io.divide_tree_io import write_divide_tree_gpkg

    validate_peak_table(result.peaks)
    validate_saddle_table(result.saddles)
    peaks = result.peaks
    layers = {} if result.depressions is None else {"depressions": result.depressions}

    def tables() -> None:
        _write_csv(peaks, out / "peaks.csv")
        _write_parquet(peaks, out / "peaks.parquet", result.crs)
        _write_parquet(result.saddles, out / "saddles.parquet", result.crs)
        if result.depressions is not None:
            _write_parquet(result.depressions, out / "depressions.parquet")

    # the GeoPackage (the slowest file) in a second thread, the other tables meanwhile in this one
    # (GDAL and Arrow release the GIL); one thread per file cost ~45 MB more peak memory at 15 M cells (malloc
    # arenas). With two cores or more, the GeoPackage's saddles and ridges go to a third thread (its wall time
    # was twice the CSV's and Parquet's)
    with ThreadPoolExecutor(1) as pool:
        gpkg = pool.submit(write_divide_tree_gpkg, result.tree, out / "dividetree.gpkg", peaks=peaks,
                           layers=layers, parallel=_cores() > 1)
        try:
            tables()
        finally:
            gpkg.result()  # the first failure is raised; analysis.json is then not written
    write_text_atomic(out / "analysis.json", analysis_json(result))
    return out


def _cores() -> int:
    """Cores this process may run on (its CPU affinity, e.g. under ``taskset``)."""
    import os

    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def _write_parquet(frame, path: Path, crs: Any = None, batch_rows: int | None = None) -> None:
    """A table as GeoParquet (point geometry from ``x``/``y``), in row groups of ``batch_rows``.

    ``frame``: a GeoDataFrame, or a DataFrame or :class:`~orokit.topology.tables.TableBlocks`
    without geometry (points are made from ``x``/``y`` in ``crs``). The file is that of
    ``GeoDataFrame.to_parquet`` (the same bytes while the table fits in one row group;
    beyond, the same table in row groups of ``batch_rows``). Only the schema goes through
    pandas (from the first row; geopandas only for a GeoDataFrame, :func:`_geoparquet_schema`
    otherwise); each row group's columns go to Arrow without copies and its points straight to WKB.
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    from orokit.io.divide_tree_gpkg import WRITE_BATCH_ROWS
    from orokit.io.wkb import point_wkb

    step = batch_rows or WRITE_BATCH_ROWS
    n = len(frame)
    gpd = sys.modules.get("geopandas")  # a GeoDataFrame exists only once geopandas is imported
    has_geometry = gpd is not None and isinstance(frame, gpd.GeoDataFrame)
    head = table_rows(frame, 0, 1)
    if has_geometry:
        from geopandas.io.arrow import _geopandas_to_arrow

        geometry_name = frame.geometry.name
        schema = _geopandas_to_arrow(head).schema
    else:
        geometry_name = "geometry"
        schema = _geoparquet_schema(head, crs)
    schema = schema.with_metadata(_whole_table_metadata(schema.metadata, frame, n))
    with atomic_path(path) as tmp, pq.ParquetWriter(str(tmp), schema, compression="snappy") as writer:
        # one row group at a time, its points made for it: no WKB of the whole table (~25 bytes per row)
        for start in range(0, max(n, 1), step):
            rows = table_rows(frame, start, min(n, start + step))
            arrays = []
            for field in schema:
                if field.name == geometry_name:
                    arrays.append(_geometry_wkb(rows.geometry.values) if has_geometry
                                  else point_wkb(rows["x"].to_numpy(np.float64), rows["y"].to_numpy(np.float64)))
                elif field.name in rows.columns:
                    arrays.append(pa.Array.from_pandas(rows[field.name], type=field.type))
                else:  # an index stored as a column (not a RangeIndex)
                    arrays.append(pa.Array.from_pandas(rows.index.get_level_values(field.name), type=field.type))
            writer.write_table(pa.Table.from_arrays(arrays, schema=schema))
            del arrays, rows


def _geoparquet_schema(head, crs: Any):
    """The Arrow schema ``GeoDataFrame.to_parquet`` gives ``head`` (a DataFrame with ``x``, ``y``)
    with point geometries from them in ``crs``, without importing geopandas or shapely (~34 MiB
    resident with pyogrio): its ``pandas`` and ``geo`` metadata (GeoParquet 1.1.0, the
    geometry's WKB field with its ``geoarrow.wkb`` extension metadata), key for key.
    """
    import pyarrow as pa

    frame = head.copy(deep=False)
    frame.attrs = {}  # geopandas's frame of the attributes has none (they go to PANDAS_ATTRS)
    frame["geometry"] = None  # as geopandas does: a null column, then the WKB field put in its place
    schema = pa.Schema.from_pandas(frame, preserve_index=None)
    projjson = None if crs is None else _pyproj_crs(crs).to_json_dict()
    extension = {"ARROW:extension:name": "geoarrow.wkb",
                 "ARROW:extension:metadata": "{}" if projjson is None else json.dumps({"crs": projjson})}
    i = schema.get_field_index("geometry")
    schema = schema.set(i, pa.field("geometry", pa.binary(), nullable=True, metadata=extension))
    column: dict[str, Any] = {"encoding": "WKB", "crs": None if projjson is None else _without_member_ids(projjson),
                              "geometry_types": ["Point"] if len(head) else []}
    if len(head):
        x, y = float(head["x"].iloc[0]), float(head["y"].iloc[0])
        if np.isfinite([x, y]).all():
            column["bbox"] = [x, y, x, y]
    geo = {"primary_column": "geometry", "columns": {"geometry": column}, "version": "1.1.0",
           "creator": {"library": "geopandas", "version": _geopandas_version()}}
    meta = dict(schema.metadata)
    meta[b"geo"] = json.dumps(geo).encode()
    if head.attrs:
        meta[b"PANDAS_ATTRS"] = json.dumps(head.attrs).encode()
    return schema.with_metadata(meta)


def _pyproj_crs(crs: Any):
    from pyproj import CRS

    return CRS.from_user_input(crs)


def _without_member_ids(projjson: dict) -> dict:
    """PROJJSON without the ids of datum ensemble members, as geopandas writes it in ``geo`` (for older
    PROJ; like geopandas, through nested objects only, not lists)."""
    out = json.loads(json.dumps(projjson))

    def strip(value: dict) -> None:
        for key, v in value.items():
            if isinstance(v, dict):
                strip(v)
            elif key == "members" and isinstance(v, list):
                for member in v:
                    member.pop("id", None)

    strip(out)
    return out


def _geopandas_version() -> str:
    """The installed geopandas's version (the ``creator`` of GeoParquet's metadata), without importing it."""
    from importlib.metadata import version

    return version("geopandas")


def _geometry_wkb(geometry):
    """Geometries as an Arrow binary array of WKB (as geopandas writes them to GeoParquet)."""
    import pyarrow as pa
    import shapely

    return pa.array(shapely.to_wkb(geometry, flavor="iso"), type=pa.binary())


def _whole_table_metadata(meta: dict, frame, n: int) -> dict:
    """A batch's Arrow metadata made that of the whole table: the index range and the bounding box."""
    meta = dict(meta)
    pandas_meta = json.loads(meta[b"pandas"])
    for index in pandas_meta.get("index_columns", []):
        if isinstance(index, dict) and index.get("kind") == "range":
            index["start"], index["stop"] = 0, n
    meta[b"pandas"] = json.dumps(pandas_meta).encode()
    geo = json.loads(meta[b"geo"])
    column = geo["columns"]["geometry"]
    if n and "bbox" in column:
        if "geometry" in frame.columns:
            column["bbox"] = frame.total_bounds.tolist()
        else:
            x, y = frame["x"].to_numpy(), frame["y"].to_numpy()
            column["bbox"] = [float(np.nanmin(x)), float(np.nanmin(y)), float(np.nanmax(x)), float(np.nanmax(y))]
    meta[b"geo"] = json.dumps(geo).encode()
    return meta


def _write_csv(frame, path: Path, batch_rows: int | None = None) -> None:
    """A (Geo)DataFrame or :class:`~orokit.topology.tables.TableBlocks` without its geometry as CSV,
    index first, floats in full precision, by blocks of ``batch_rows`` rows.

    Each block's columns go to Arrow without copies and to Arrow's CSV writer (the bytes
    of one ``write_csv`` of the whole table).
    """
    import pyarrow as pa
    import pyarrow.csv as pacsv

    from orokit.io.divide_tree_gpkg import WRITE_BATCH_ROWS

    step = batch_rows or WRITE_BATCH_ROWS
    n = len(frame)
    with atomic_path(path) as tmp:
        writer = None
        try:
            for start in range(0, max(n, 1), step):
                rows = table_rows(frame, start, min(n, start + step))
                columns = [c for c in rows.columns if c != "geometry"]
                names = [rows.index.name or "index", *columns]
                arrays = [pa.Array.from_pandas(rows.index), *(pa.Array.from_pandas(rows[c]) for c in columns)]
                table = pa.Table.from_arrays(arrays, names=names)
                if writer is None:
                    writer = pacsv.CSVWriter(str(tmp), table.schema)
                writer.write_table(table)
                del rows, arrays, table
        finally:
            if writer is not None:
                writer.close()


def read_analysis(outdir: PathLike) -> AnalysisResult:
    """Read a folder written by :func:`write_analysis`."""
    import geopandas as gpd

    from orokit.io.divide_tree_io import read_divide_tree_gpkg

    out = Path(outdir)
    meta_path = out / "analysis.json"
    if not meta_path.exists():
        raise InputError(f"{out} is not a complete orokit analysis folder (no analysis.json); rerun `orokit analyze`")
    meta = read_analysis_meta(out)
    peaks = gpd.read_parquet(out / "peaks.parquet")
    validate_peak_table(peaks, source=str(out / "peaks.parquet"))
    saddles = gpd.read_parquet(out / "saddles.parquet")
    validate_saddle_table(saddles, source=str(out / "saddles.parquet"))
    tree = read_divide_tree_gpkg(out / "dividetree.gpkg")
    crs = peaks.crs
    meta.pop("crs", None)
    dep_path = out / "depressions.parquet"
    depressions = gpd.read_parquet(dep_path) if dep_path.exists() else None
    return AnalysisResult(peaks, saddles, tree, crs, meta, depressions)


def read_analysis_meta(outdir: PathLike) -> dict[str, Any]:
    """``analysis.json`` of an analysis folder, keys of older orokit versions renamed (``upgrade_attrs``).

    Raises
    ------
    InputError
        No readable ``analysis.json`` (not an analysis folder) or not a JSON object.
    """
    meta = read_json_file(Path(outdir) / "analysis.json", what="analysis metadata")
    if not isinstance(meta, dict):
        raise InputError(f"{Path(outdir) / 'analysis.json'} is not a JSON object; rerun `orokit analyze`")
    return upgrade_attrs(meta)


def read_peak_cells(outdir: PathLike) -> pd.DataFrame:
    """The raster cell and place of every peak of an analysis folder: ``row``, ``col``, ``x``, ``y``."""
    p = Path(outdir) / "peaks.parquet"
    if not p.exists():
        raise InputError(f"no peaks table at {p}; pass an `orokit analyze` output folder")
    import pandas as pd

    return pd.read_parquet(p, columns=["row", "col", "x", "y"])


def read_peaks(source: PathLike):
    """Peaks table of an analysis folder, a peaks.parquet or a peaks.csv file."""
    import geopandas as gpd

    p = Path(source)
    if p.is_dir():
        p = p / "peaks.parquet"
    if not p.exists():
        raise InputError(f"no peaks table at {p}")
    import pandas as pd

    fix = "pass an `orokit analyze` output folder, its peaks.parquet or its peaks.csv"
    parquet = p.suffix.lower() == ".parquet"
    try:
        frame = gpd.read_parquet(p) if parquet else pd.read_csv(p)
    except (ValueError, OSError, UnicodeDecodeError) as exc:  # pyarrow's and pandas' parse errors are ValueErrors
        why = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise InputError(f"{p} is not a readable peaks table ({why}); {fix}") from None
    if not parquet:
        if "peak_id" not in frame.columns:
            columns = ", ".join(map(str, frame.columns)) or "none"
            raise InputError(f"{p} has no peak_id column (columns: {columns}); {fix}")
        frame = frame.set_index("peak_id")
    missing = [c for c in ("x", "y") if c not in frame.columns]
    if missing:
        raise InputError(f"{p} has no {' and '.join(missing)} column; {fix}")
    if parquet:
        return frame
    return gpd.GeoDataFrame(frame, geometry=gpd.points_from_xy(frame["x"], frame["y"]))
