"""Divide Tree files as GeoPackage layers (``peaks``, ``saddles``, ``ridges``)."""
from __future__ import annotations

import itertools
import json
import logging
from collections.abc import Callable
from contextlib import AbstractContextManager
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from orokit._typing import PathLike
from orokit.errors import InputError
from orokit.io.atomic import atomic_path, temp_path_for
from orokit.topology.divide_tree import DivideTree
from orokit.topology.tables import TableBlocks, table_rows, upgrade_attrs
from orokit.topology.tree_checks import check_read_tree

logger = logging.getLogger(__name__)

__all__ = ["write_divide_tree_gpkg", "read_divide_tree_gpkg"]


def _json_attrs(attrs: dict) -> dict:
    out = {}
    for k, v in attrs.items():
        if isinstance(v, (pd.DataFrame, pd.Series)):
            continue
        if isinstance(v, np.generic):
            v = v.item()
        try:
            json.dumps(v)
        except (TypeError, ValueError):
            logger.debug("attribute %r (%s) is not JSON-serialisable; not written", k, type(v).__name__)
            continue
        out[k] = v
    return out


#: rows per row group of the GeoParquet tables
WRITE_BATCH_ROWS = 65_536
#: how every layer is written: through GDAL's Arrow interface, without spatial index (GIS tools
#: build one on demand; it would double the writing time)
_LAYER_OPTIONS = {"SPATIAL_INDEX": "NO"}
_GPKG = {"driver": "GPKG", "layer_options": _LAYER_OPTIONS}


def _gdal_crs(crs) -> str | None:
    """A CRS (pyproj CRS or anything it reads, e.g. "EPSG:32633") as GDAL takes it (what geopandas passes):
    ``EPSG:n`` when it has a code, else WKT1."""
    if crs is None:
        return None
    if not hasattr(crs, "to_epsg"):  # a string or EPSG code, as trees built in memory may carry
        from pyproj import CRS

        crs = CRS.from_user_input(crs)
    epsg = crs.to_epsg()
    return f"EPSG:{epsg}" if epsg else crs.to_wkt("WKT1_GDAL")


def _sqlite_without_sync() -> AbstractContextManager[bool]:
    """GDAL's SQLite does not sync each transaction to disk in this thread while the block runs.

    For a temporary GeoPackage that :func:`~orokit.io.atomic.atomic_path` syncs once and
    renames when complete: the per-transaction syncs only cost time (~30 % of the
    GeoPackage's wall time at 100,890 peaks, measured in session 10; 74 syncs -> 2 for a
    25,308-peak file, session 13). Thread-local (:func:`~orokit.io.gdal_arrow.thread_config_option`):
    the process's setting, and other threads' writers, are left as they were.
    """
    from orokit.io.gdal_arrow import thread_config_option

    return thread_config_option("OGR_SQLITE_SYNCHRONOUS", "OFF")


def _ids(start: int, stop: int) -> np.ndarray:
    """Row ids ``start..stop - 1`` of a layer's batch."""
    return np.arange(start, stop, dtype=np.int64)


def _column_at(frame: Any, name: str) -> Callable[[np.ndarray], np.ndarray]:
    """``at(positions)``: the float column ``name`` of a DataFrame (held whole) or of a
    :class:`~orokit.topology.tables.TableBlocks` (made at those rows only) at some rows."""
    if isinstance(frame, TableBlocks):
        return lambda at: frame.take(name, at).astype(np.float64, copy=False)
    values = frame[name].to_numpy(np.float64)
    return lambda at: values[at]


def write_divide_tree_gpkg(tree: DivideTree, path: PathLike, *, peaks: pd.DataFrame | None = None,
                           layers: dict | None = None, parallel: bool = False) -> Path:
    """Write ``tree`` as a GeoPackage with layers ``peaks``, ``saddles`` and ``ridges``.

    ``ridges`` holds LineStrings peak_a -> saddle -> peak_b with the columns
    ``peak_a``, ``peak_b``, ``saddle`` (0-based ids into the ``peak_id``/``saddle_id``
    columns of the point layers). Runoffs and basin saddles kept in ``tree.attrs`` go
    to layers ``runoffs`` and ``basin_saddles``; the JSON-serialisable attrs go to the
    dataset metadata (key ``orokit_attrs``). The file is written atomically.

    ``peaks``: the peaks table of the same tree (same ids, :data:`~orokit.topology.tables.PEAK_SCHEMA`,
    e.g. ``AnalysisResult.peaks``); its orometry columns (prominence, key saddle, parents,
    dominance, isolation, exactness flags) are added to the ``peaks`` layer, so a GIS user
    needs no join. :func:`read_divide_tree_gpkg` leaves them out of the tree (they are
    derived: ``tree.prominence_table()`` recomputes them).

    ``layers``: further point GeoDataFrames by layer name (e.g. ``depressions``).

    The layers go through GDAL's C API without the GIL (:mod:`orokit.io.gdal_arrow`;
    pyogrio's writer, which holds it, when that library is not found), so other Python
    threads run while GDAL writes.

    ``parallel``: the ``saddles`` and ``ridges`` layers are written into a second
    GeoPackage by a second thread while this one writes ``peaks``, then copied into the
    file by SQLite (:func:`_merge_layers`); the same layers, in the same order. GDAL
    writes a layer at ~1-4 us per row in one thread, so this halves the file's wall time
    with two idle cores (one core: use False, the copy costs ~0.1 s per 100,000 rows).
    """
    import pyarrow as pa

    from orokit.io.gdal_arrow import gdal_library, write_arrow_layer
    from orokit.io.wkb import point_wkb, polyline_wkb
    from orokit.topology.tables import OROMETRY_COLUMNS, validate_peak_table

    path = Path(path)
    tree.validate(check_elevations=False)
    added: list[str] = []
    if peaks is not None:
        validate_peak_table(peaks)
        if len(peaks) != tree.n_peaks:
            raise InputError(f"the peaks table has {len(peaks)} rows but the tree {tree.n_peaks} peaks; "
                             "pass the table of the same tree")
        added = [c for c in OROMETRY_COLUMNS if c not in tree.peaks.columns]
    meta = {"orokit_attrs": json.dumps(_json_attrs(tree.attrs)), "orometry_columns": json.dumps(added)}

    crs = _gdal_crs(tree.crs)

    def write(dst: Path, columns: dict[str, Any], wkb, n: int, layer: str, geometry_type: str, more=None) -> None:
        """One layer from whole columns (no copies), in one write streamed by batches of
        ``WRITE_BATCH_ROWS`` rows; ``wkb(start, stop)`` makes the geometries of a batch, so no
        geometry column of the whole layer is ever held (the ridges': ~90 bytes per ridge);
        a column given as a function ``f(start, stop)`` is made for each batch (ids, gathers);
        ``more(start, stop)``: further columns made for the batch (a dict, after ``columns``)."""

        def rows(v, start: int, stop: int):
            if callable(v):
                return v(start, stop)
            return v.iloc[start:stop] if isinstance(v, pd.Series) else v[start:stop]

        def batches():
            types = None  # the first batch's column types, kept by the others
            for start in range(0, max(n, 1), WRITE_BATCH_ROWS):
                stop = min(n, start + WRITE_BATCH_ROWS)
                values = [rows(v, start, stop) for v in columns.values()]
                names = list(columns)
                if more is not None:
                    extra = more(start, stop)
                    values += list(extra.values())
                    names += list(extra)
                arrays = [pa.Array.from_pandas(v, type=None if types is None else types[i])
                          for i, v in enumerate(values)]
                types = [a.type for a in arrays]
                del values
                yield pa.RecordBatch.from_arrays([*arrays, wkb(start, stop)], names=[*names, "geometry"])

        stream = batches()
        first = next(stream)
        schema = first.schema
        if gdal_library() is not None:  # GDAL without the GIL: the other writers' threads run meanwhile
            write_arrow_layer(dst, layer, schema, itertools.chain([first], stream), geometry_name="geometry",
                              geometry_type=geometry_type, crs=crs, layer_options=_LAYER_OPTIONS)
            return
        import pyogrio

        reader = pa.RecordBatchReader.from_batches(schema, itertools.chain([first], stream))
        del first
        pyogrio.write_arrow(reader, dst, layer=layer, geometry_name="geometry", geometry_type=geometry_type, crs=crs,
                            **_GPKG)

    def points(dst: Path, frame: Any, id_name: str, layer: str, extra: Any = None) -> None:
        """A point layer of ``frame``'s columns (a DataFrame, or a TableBlocks whose rows are made batch
        by batch), then the ``added`` columns of ``extra`` (a table with the same rows: a DataFrame or
        TableBlocks, whose rows are taken batch by batch)."""
        # the ids made per batch: no column of the whole layer (8 bytes per row)
        columns: dict[str, Any] = {id_name: _ids}
        lazy = isinstance(frame, TableBlocks)
        names = list(frame.columns)
        if not lazy:
            columns.update((c, frame[c]) for c in names)
        batch: dict[str, Any] = {}  # the TableBlocks' rows of the batch being written (for its points)

        def more(i: int, j: int) -> dict[str, Any]:
            out: dict[str, Any] = {}
            if lazy:
                block = batch["rows"] = frame.block(i, j)
                out.update((c, block[c]) for c in names)
            if extra is not None:
                block = table_rows(extra, i, j)
                out.update((c, block[c]) for c in added)
            return out

        if lazy:
            def wkb(i: int, j: int):
                rows = batch.pop("rows")
                return point_wkb(rows["x"].to_numpy(np.float64), rows["y"].to_numpy(np.float64))
        else:
            x, y = frame["x"].to_numpy(np.float64), frame["y"].to_numpy(np.float64)

            def wkb(i: int, j: int):
                return point_wkb(x[i:j], y[i:j])
        write(dst, columns, wkb, len(frame), layer, "Point", more if lazy or extra is not None else None)

    def saddles_and_ridges(dst: Path) -> None:
        with _sqlite_without_sync():  # this thread's setting (the parallel writer's is its own)
            _saddles_and_ridges(dst)

    def _saddles_and_ridges(dst: Path) -> None:
        points(dst, tree.saddles, "saddle_id", "saddles")
        a, b, s = tree._edge_arrays()
        px, py, sx, sy, sz = (_column_at(frame, c) for frame, c in ((tree.peaks, "x"), (tree.peaks, "y"),
                                                                    (tree.saddles, "x"), (tree.saddles, "y"),
                                                                    (tree.saddles, "elevation")))
        ridges: dict[str, Any] = {c: tree.edges[c] for c in tree.edges.columns}
        ridges["saddle_elevation"] = lambda i, j: sz(s[i:j])  # per batch: no gathered column of every ridge

        def lines(i: int, j: int):
            ai, bi, si = a[i:j], b[i:j], s[i:j]
            return polyline_wkb(np.stack([px(ai), sx(si), px(bi)], axis=1), np.stack([py(ai), sy(si), py(bi)], axis=1))

        write(dst, ridges, lines, len(a), "ridges", "LineString")

    # no warnings.catch_warnings here: this may run in a writer thread, and the filters it swaps are the
    # process's (other threads' filters and recorders were lost or leaked). A tree on a local grid has
    # no CRS (recorded in attrs); GDAL's C API writes it without pyogrio's warning about that
    with atomic_path(path) as tmp, _sqlite_without_sync():
        if parallel:
            from concurrent.futures import ThreadPoolExecutor

            aux = temp_path_for(path)
            try:
                with ThreadPoolExecutor(1) as pool:
                    second = pool.submit(saddles_and_ridges, aux)
                    try:
                        points(tmp, tree.peaks, "peak_id", "peaks", peaks)
                    finally:
                        second.result()  # joined; its failure is raised (with this thread's as context)
                _merge_layers(tmp, aux, ["saddles", "ridges"])
            finally:
                aux.unlink(missing_ok=True)
        else:
            points(tmp, tree.peaks, "peak_id", "peaks", peaks)
            saddles_and_ridges(tmp)
        for key in ("runoffs", "basin_saddles"):
            extra = tree.attrs.get(key)
            if isinstance(extra, pd.DataFrame):
                points(tmp, extra, "point_id", key)
        for name, frame in (layers or {}).items():
            _write_point_frame(tmp, name, frame.reset_index())
        # attrs go to a small non-spatial table (portable across GDAL versions)
        _write_metadata(tmp, meta)
    logger.info("wrote %s: %d peaks, %d ridges", path, tree.n_peaks, len(tree.edges))
    return path


def _write_point_frame(path: Path, layer: str, frame: Any) -> None:
    """The point GeoDataFrame ``frame`` as the layer ``layer`` of ``path``: the layer ``to_file`` (pyogrio,
    through Arrow) writes, through GDAL's C API when found (pyogrio warns of a missing CRS; its writer
    otherwise, which then does)."""
    import pyarrow as pa
    import shapely

    from orokit.io.gdal_arrow import gdal_library, write_arrow_layer

    if gdal_library() is None:
        frame.to_file(path, layer=layer, geometry_type="Point", engine="pyogrio", use_arrow=True, **_GPKG)
        return
    name = frame.geometry.name
    table = pd.DataFrame(frame, copy=False).assign(**{name: shapely.to_wkb(frame.geometry.values)})
    batch = pa.Table.from_pandas(table, preserve_index=False)
    write_arrow_layer(path, layer, batch.schema, batch.to_batches(), geometry_name=name, geometry_type="Point",
                      crs=_gdal_crs(frame.crs), layer_options=_LAYER_OPTIONS)


def _write_metadata(path: Path, meta: dict[str, str]) -> None:
    """``meta`` as the non-spatial layer ``orokit_metadata`` (string columns ``key``, ``value``) of ``path``."""
    import pyarrow as pa

    from orokit.io.gdal_arrow import gdal_library, write_arrow_layer

    table = pa.table({"key": pa.array(list(meta), pa.string()), "value": pa.array(list(meta.values()), pa.string())})
    if gdal_library() is not None:
        write_arrow_layer(path, "orokit_metadata", table.schema, table.to_batches(), geometry_name=None,
                          geometry_type=None, crs=None, layer_options={})
        return
    import pyogrio

    pyogrio.write_dataframe(table.to_pandas(), path, layer="orokit_metadata", driver="GPKG")


#: GeoPackage tables that describe a layer by a ``table_name`` column (those present in both files are copied)
_GPKG_LAYER_TABLES = ("gpkg_contents", "gpkg_geometry_columns", "gpkg_ogr_contents", "gpkg_extensions",
                      "gpkg_data_columns")


def _merge_layers(path: Path, other: Path, layers: list[str]) -> None:
    """Copy ``layers`` of the GeoPackage ``other`` into the GeoPackage ``path`` (both written by GDAL).

    In one SQLite transaction: each layer's table, rows (fids kept), indexes and triggers,
    its rows of the GeoPackage tables that describe layers (contents with the extent,
    geometry column, feature count, extensions) and the spatial reference systems
    ``path`` lacks. GDAL then reads the layers as if it had written them into ``path``.
    """
    import sqlite3

    con = sqlite3.connect(str(path), isolation_level=None)
    try:
        con.execute("PRAGMA synchronous = OFF")  # the file is synced once by atomic_path
        con.execute("ATTACH DATABASE ? AS other", (str(other),))
        con.execute("BEGIN")
        tables = {name for (name,) in con.execute("SELECT name FROM main.sqlite_master WHERE type = 'table'")}
        theirs = {name for (name,) in con.execute("SELECT name FROM other.sqlite_master WHERE type = 'table'")}
        con.execute("INSERT OR IGNORE INTO main.gpkg_spatial_ref_sys SELECT * FROM other.gpkg_spatial_ref_sys")
        for layer in layers:
            if layer in tables:
                raise InputError(f"{path} already has a layer {layer!r}")
            (sql,) = con.execute("SELECT sql FROM other.sqlite_master WHERE type = 'table' AND name = ?",
                                 (layer,)).fetchone()
            con.execute(sql)  # CREATE TABLE "layer" (...): in main
            quoted = '"' + layer.replace('"', '""') + '"'
            con.execute(f"INSERT INTO main.{quoted} SELECT * FROM other.{quoted}")
            for table in _GPKG_LAYER_TABLES:
                if table in tables and table in theirs:
                    con.execute(f"INSERT INTO main.{table} SELECT * FROM other.{table} WHERE table_name = ?", (layer,))
            # after the rows: the feature-count triggers would otherwise count them a second time
            for (sql,) in con.execute("SELECT sql FROM other.sqlite_master WHERE type IN ('index', 'trigger') AND "
                                      "tbl_name = ? AND sql IS NOT NULL ORDER BY type, rowid", (layer,)).fetchall():
                con.execute(sql)
        con.execute("COMMIT")
        con.execute("DETACH DATABASE other")
    finally:
        con.close()


def read_divide_tree_gpkg(path: PathLike) -> DivideTree:
    """Read a Divide Tree written by :func:`write_divide_tree_gpkg`.

    Raises
    ------
    InputError
        If the file does not exist or lacks the ``peaks``, ``saddles`` or ``ridges``
        layers or their id columns.
    DivideTreeError
        The content is no Divide Tree (see :func:`orokit.topology.tree_checks.check_read_tree`).
    """
    import geopandas as gpd
    import pyogrio

    path = Path(path)
    if not path.is_file():
        raise InputError(f"Divide Tree GeoPackage {path} does not exist or is not a file")
    try:
        layers = {name for name, _ in pyogrio.list_layers(path)}
    except Exception as exc:  # pyogrio raises DataSourceError and friends
        raise InputError(f"{path} is not a readable GeoPackage: {exc}") from None
    missing = {"peaks", "saddles", "ridges"} - layers
    if missing:
        raise InputError(
            f"{path} lacks the layers {sorted(missing)} (found {sorted(layers)}); "
            "write it with orokit.io.divide_tree_io.write_divide_tree_gpkg"
        )

    def frame(layer: str, id_name: str) -> tuple[pd.DataFrame, Any]:
        g = gpd.read_file(path, layer=layer, engine="pyogrio")
        if id_name not in g.columns:
            raise InputError(f"{path}: layer {layer!r} lacks the column {id_name!r}")
        crs = g.crs
        f = pd.DataFrame(g.drop(columns="geometry")).sort_values(id_name).reset_index(drop=True)
        if not np.array_equal(f[id_name].to_numpy(), np.arange(len(f))):
            raise InputError(f"{path}: layer {layer!r} column {id_name!r} is not 0..n-1")
        return f.drop(columns=id_name), crs

    peaks, crs = frame("peaks", "peak_id")
    saddles, _ = frame("saddles", "saddle_id")
    r = gpd.read_file(path, layer="ridges", engine="pyogrio")
    missing_cols = {"peak_a", "peak_b", "saddle"} - set(r.columns)
    if missing_cols:
        raise InputError(f"{path}: layer 'ridges' lacks the columns {sorted(missing_cols)}")
    edges = pd.DataFrame(r[["peak_a", "peak_b", "saddle"]]).astype(np.int64).reset_index(drop=True)
    attrs: dict[str, Any] = {}
    if "orokit_metadata" in layers:
        meta = pyogrio.read_dataframe(path, layer="orokit_metadata")
        for k, v in zip(meta["key"], meta["value"]):
            if k == "orokit_attrs":
                attrs.update(upgrade_attrs(json.loads(v), geographic=False))  # TXT trees: metres
            elif k == "orometry_columns":  # derived columns for GIS users, not part of the tree
                peaks = peaks.drop(columns=[c for c in json.loads(v) if c in peaks.columns])
    for key in ("runoffs", "basin_saddles"):
        if key in layers:
            attrs[key], _ = frame(key, "point_id")
    return check_read_tree(DivideTree(peaks, saddles, edges, crs, attrs), str(path))
