"""``orokit.analyze``: exact orometry of one elevation raster.

From a DEM to the peaks table (prominence, key saddle, parent, dominance, isolation,
exactness flags), the saddles table and the Divide Tree pruned at a prominence
threshold. The in-memory engine is in :mod:`orokit.topology.engine`; this module
holds the public function, the result object and its files.
"""
from __future__ import annotations

import logging
import threading
import time
from pathlib import Path
from typing import Any, Literal

import numpy as np

from orokit import __version__
from orokit.errors import InputError
from orokit.geodesy import cell_size_attrs
from orokit._typing import PathLike
from orokit.topology.tables import PEAK_COLUMNS, AnalysisResult, upgrade_attrs

logger = logging.getLogger(__name__)

__all__ = ["analyze", "AnalysisResult", "read_analysis", "write_analysis", "PEAK_COLUMNS"]


def read_analysis(outdir: PathLike) -> AnalysisResult:
    """Read a folder written by :func:`write_analysis` / ``orokit analyze``."""
    from orokit.io.analysis_io import read_analysis as _read

    return _read(outdir)


def write_analysis(result: AnalysisResult, outdir: str | Path, *, overwrite: bool = False) -> Path:
    """Write peaks.csv, peaks.parquet, saddles.parquet, dividetree.gpkg, analysis.json into ``outdir``."""
    from orokit.io.analysis_io import write_analysis as _write

    return _write(result, outdir, overwrite=overwrite)


def analyze(
    dem,
    *,
    min_prominence_m: float = 30.0,
    outside: Literal["unknown", "sea"] = "unknown",
    isolation: bool = True,
    progress: bool = False,
    z_units: str | None = None,
    cell_size_m: float | None = None,
    chunks: int | tuple[int, int] | None = None,
    scheduler: Any = None,
    checkpoint: str | Path | None = None,
    depressions: bool = False,
    sea_level_m: float | None = None,
    dem_error_m: float | None = None,
    error_k: float = 2.0,
    error_corr_m: float = 0.0,
    samples: int = 0,
    seed: int | None = None,
    geometry: bool = True,
    blocks: bool = False,
    release_dem: bool = False,
) -> AnalysisResult:
    """Peaks, key saddles, prominence, dominance, isolation and the Divide Tree.

    Parameters
    ----------
    dem : DataArray from :func:`orokit.io.dem.read_dem` (dims y, x; metres; NaN =
        nodata; CRS and transform through rioxarray), a
        :class:`~orokit.io.dem.DemArray` from :func:`~orokit.io.dem.read_dem_array`,
        or a path to read with it.
    min_prominence_m : keep peaks with prominence >= this many metres (0 = every peak).
    outside : what lies beyond the data (raster edge and NaN cells). ``"unknown"``
        (default): prominences whose key saddle is below a path to the edge are upper
        bounds and flagged ``prominence_exact=False``. ``"sea"``: the outside is sea,
        every prominence is exact.
    isolation : compute isolation (nearest strictly higher cell).
    progress : show a progress bar over the stages.
    z_units, cell_size_m : forwarded to ``read_dem`` when ``dem`` is a path.
    chunks : cells per chunk side (int or (rows, cols)). When given, or when ``dem``
        is dask-backed, the raster is analysed chunk by chunk (out of core) with the
        exact tiled engine; results are identical to the in-memory engine.
    scheduler : dask scheduler for the chunked engine: None (default threads or the
        active distributed client), a name, a ``distributed.Client`` or an address.
    checkpoint : folder for chunk summaries; a rerun with it reuses finished chunks.
    depressions : also find the depressions (pits) with depth >= ``min_prominence_m``:
        the same engine on ``-h`` (same tie rules and edge flags), in
        ``result.depressions`` (:data:`orokit.topology.depressions.DEPRESSION_COLUMNS`).
        With ``outside="sea"`` a depression that reaches the edge spills into the sea.
    sea_level_m : with ``depressions``, cells at or below this elevation are sea: land
        depressions spill into it and no pit is reported inside it.
    dem_error_m : standard deviation sigma of the DEM error (metres). Adds
        ``prominence_low`` / ``prominence_high``: guaranteed bounds for any error of at
        most ``error_k * sigma`` (:func:`orokit.topology.uncertainty.prominence_bounds`).
    error_k, error_corr_m, samples, seed : with ``samples`` > 0 (in memory only), that
        many realisations of Gaussian error of correlation length ``error_corr_m``
        (seeded by ``seed``; None = fresh entropy, recorded in ``attrs["seed"]``) add
        ``p_exists`` (share of realisations with a peak of prominence >= the threshold
        within one correlation length, at least one cell) and ``prominence_median``.
    geometry : False: ``peaks`` and ``saddles`` are plain DataFrames without point
        geometries (``x``/``y`` hold the places), about half the memory per peak;
        :func:`write_analysis` writes the same files from them.
    blocks : True: ``peaks`` is a :class:`~orokit.topology.tables.TableBlocks` (no point
        geometries) whose rows are made from the engine's arrays by blocks of rows when
        :func:`write_analysis` writes them: the same files, ~130 bytes per peak less held
        at once (what ``orokit analyze`` runs). ``peaks[name]`` gives one whole column,
        ``peaks.to_frame()`` the DataFrame. ``saddles`` and the tree's ``peaks`` and
        ``saddles`` frames are TableBlocks too, their places (row, col, x, y, elevation)
        made from the cells when read (~56 bytes per peak less).
    release_dem : True: in memory, the pixels of a :class:`~orokit.io.dem.DemArray` are
        released (:meth:`~orokit.io.dem.DemArray.release`) once no step needs them, after
        the isolation search, so the tables are built without them (what ``orokit
        analyze`` runs: 4 bytes per cell). Not with ``dem_error_m`` or ``depressions``,
        which read the DEM again.

    Returns
    -------
    AnalysisResult

    Notes
    -----
    Conventions (those of Kirmse's prominence program where it has one):

    1. 8-neighbourhood for peaks and saddles. Cells are ordered by elevation, ties by
       raster order (the first cell in raster order counts as higher). A flat summit
       is one peak, reported at its first cell in raster order; among equal-height
       peaks the one whose cell comes first in raster order counts as higher.
    2. NaN (nodata) cells count as lower than everything and never carry a path.
       Input values are never altered.
    3. The highest peak of each 8-connected domain of valid cells has no key saddle;
       its prominence is its elevation (the paper's convention) and it is flagged not
       exact unless ``outside="sea"``. It is kept when its elevation reaches the
       threshold or when another peak of its domain is kept (every kept peak's
       parent is in the table). A domain that is entirely flat has no peak.
    4. Pruning at ``min_prominence_m`` keeps every surviving peak's exact prominence.
    """
    from orokit.topology import engine

    t0 = time.perf_counter()
    if outside not in ("unknown", "sea"):
        raise InputError(f"outside must be 'unknown' or 'sea', got {outside!r}")
    if not np.isfinite(min_prominence_m) or min_prominence_m < 0:
        raise InputError(f"min_prominence_m must be a finite number >= 0 (metres), got {min_prominence_m!r}")
    if not hasattr(dem, "dims"):
        from orokit.io.dem import read_dem

        if chunks is None:
            chunks = plan_chunks(dem)
        dem = read_dem(dem, z_units=z_units, cell_size_m=cell_size_m, chunks=chunks)
    if dem.ndim != 2:
        raise InputError(f"the DEM must be 2-D (y, x); got dims {dem.dims}")
    units = dem.attrs.get("units", "m")
    if units not in ("m", "metre", "metres", "meter", "meters"):
        from orokit.errors import UnitsError

        raise UnitsError(f"DEM elevations must be in metres (read it with read_dem(z_units=...)); attrs units={units!r}")
    transform, crs = _georef(dem)
    tiled = chunks is not None or dem.chunks is not None
    store = None  # the chunked engine's peak table: its own columns wait on disk until written
    bar = _progress(progress and not tiled, ["peaks, saddles and Divide Tree", "isolation", "tables"])
    if tiled:
        from orokit.tiling.engine import get_compute, tiled_orometry
        from orokit.tiling.isolation import cell_places, tiled_isolation

        data = dem.data
        client = None
        if isinstance(scheduler, str) and "://" in scheduler:
            from distributed import Client

            try:
                client = scheduler = Client(scheduler, set_as_default=False, timeout="20s")
            except (OSError, TimeoutError) as exc:
                from orokit.errors import TilingError

                raise TilingError(f"cannot reach the dask scheduler at {scheduler}: {exc}") from None
        try:
            if chunks is not None:
                data = data.rechunk(chunks) if hasattr(data, "rechunk") else _as_dask(data, chunks)
            from orokit.metrics.isolation import KernelMetric

            metric = KernelMetric.from_grid(transform, crs) if isolation else None
            if blocks:
                from orokit.io.spill_io import SpilledColumns
                from orokit.tiling.engine import in_process, spill_parent

                # what the search does not read (~65 bytes per peak) waits on disk until the tables; with
                # the tasks in this process the finalize puts it there as it is made
                store = SpilledColumns(parent=spill_parent(checkpoint))
            tiled_core = tiled_orometry(data, min_prominence_m=min_prominence_m, outside=outside,
                                        scheduler=scheduler, checkpoint=checkpoint, progress=progress,
                                        isolation_metric=metric,
                                        store=store if store is not None and in_process(scheduler) else None)
            core = tiled_core.orometry
            t_core = time.perf_counter()
            if store is not None and core.n_kept:
                engine.spill_orometry(core, store)
            iso = None
            if isolation and core.n_kept:
                # the places int32 and made here: the call's arguments live until it returns
                peak_rows, peak_cols = cell_places(core.peak_cell, core.shape[1])
                iso = tiled_isolation(data, peak_rows, peak_cols, core.peak_z, transform=transform,
                                      crs=crs, compute=get_compute(scheduler),
                                      chunk_stats=tiled_core.chunk_stats, known=tiled_core.chunk_isolation,
                                      release_known=True)
                del peak_rows, peak_cols
            del tiled_core  # the settled isolation's spill files go with it (the search closed them)
            if store is not None and iso is not None:  # to the store, freed before the tables are made
                for name, dtype in engine.ISOLATION_ARRAYS:
                    store.put(name, iso[name].to_numpy(dtype))
                iso = None
            t_iso = time.perf_counter()
        except BaseException:
            if store is not None:  # a failed or interrupted run leaves no column folder behind
                store.close()
            raise
        finally:
            if client is not None:
                client.close()
    else:
        z = np.asarray(dem.values)
        if not np.issubdtype(z.dtype, np.floating):
            z = z.astype(np.float64)
        z = np.ascontiguousarray(z)
        # the pixels go once the isolation search is done (the caller asked; nothing after reads them)
        release = release_dem and hasattr(dem, "release") and dem_error_m is None and not depressions
        from orokit.metrics.isolation import KernelMetric, finish_isolation, nearest_higher, search_pyramid
        from orokit.tiling.memory import release_free_heap

        graph = engine.saddle_graph(z)
        if release and not isolation:  # the finalize reads the graph only: the pixels go before it
            del z
            dem.release()
            release = False
        # the engine's peak memory is past: without isolation, the libraries of the tables and files
        # load in a second thread while this one finishes the tree (wall time: the finalize is serial).
        # With isolation, the raster is held until the search is done: the search's pyramid is built
        # once the saddle graph is freed, and the libraries load once the raster is let go (beside the
        # finalize, the pyramid, and beside the search, the libraries set the process's peak at 15 M cells)
        libraries = None if isolation else _import_in_thread(_table_libraries)
        core = engine.finalize_graph(**graph, min_prominence_m=min_prominence_m, outside=outside)
        del graph
        release_free_heap()  # the saddle graph's arrays, freed inside the heap, before the isolation's
        t_core = time.perf_counter()
        _advance(bar)
        iso = None
        if isolation and core.n_kept:
            metric = KernelMetric.from_grid(transform, crs)
            rows, cols = core.peak_row.astype(np.int64), core.peak_col.astype(np.int64)
            best, cand, edge = nearest_higher(z, rows, cols, metric, search_pyramid(z))
            width = z.shape[1]
            if release:
                del z
                dem.release()
            iso = finish_isolation(metric, rows, cols, best, cand, width, edge)
            del best, cand, edge
        elif release:
            del z
            dem.release()
        if libraries is not None:
            libraries.join()
        t_iso = time.perf_counter()
        _advance(bar)
    result = engine.build_result(core, transform=transform, crs=crs, isolation=iso, geometry=geometry,
                                blocks=blocks, store=store)
    del iso
    t_end = time.perf_counter()
    _advance(bar)
    if bar is not None:
        bar.close()
    result.attrs.update(
        {
            "orokit_version": __version__,
            "min_prominence_m": float(min_prominence_m),
            "outside": outside,
            "units": "m",
            "connectivity": 8,
            "local_grid": bool(dem.attrs.get("local_grid", crs is None)),
            "source": str(dem.attrs.get("source", "")),
            "dataset": str(dem.attrs.get("dataset", "")),
            "z_units_in": str(dem.attrs.get("z_units_in", "m")),
            **{key: list(size) for key, size in cell_size_attrs(transform, crs).items()},
            "transform": [transform.a, transform.b, transform.c, transform.d, transform.e, transform.f],
            "crs_geographic": bool(crs is not None and crs.is_geographic),
            "shape": list(dem.shape),
            "engine": "tiled" if tiled else "in-memory",
            "n_local_maxima": int(core.n_maxima),
            "timings_s": {
                "tree_and_prominence": round(t_core - t0, 4),
                "isolation": round(t_iso - t_core, 4),
                "tables": round(t_end - t_iso, 4),
            },
        }
    )
    logger.info(
        "%d peaks with prominence >= %g m (of %d maxima) in %.2f s",
        len(result.peaks), min_prominence_m, core.n_maxima, t_end - t0,
    )
    if dem_error_m is not None:
        _dem_error(result, dem, core, transform, crs, sigma_m=float(dem_error_m), k=float(error_k),
                   corr_m=float(error_corr_m), samples=int(samples), seed=seed, tiled=tiled,
                   min_prominence_m=min_prominence_m, outside=outside)
    elif samples:
        raise InputError("samples (Monte Carlo) needs dem_error_m (CLI: --dem-error SIGMA)")
    if depressions:
        result.depressions = _depressions(dem, transform, crs, min_prominence_m=min_prominence_m, outside=outside,
                                          sea_level_m=sea_level_m, chunks=chunks if tiled else None,
                                          scheduler=scheduler)
        result.attrs["sea_level_m"] = sea_level_m
        result.attrs["n_depressions"] = int(len(result.depressions))
    elif sea_level_m is not None:
        raise InputError("sea_level_m only applies to depressions; pass depressions=True (CLI: --depressions)")
    return result


def _dem_error(result, dem, core, transform, crs, *, sigma_m, k, corr_m, samples, seed, tiled,
               min_prominence_m, outside) -> None:
    """Prominence bounds (and Monte Carlo columns) under DEM error, added to ``result.peaks``."""
    from orokit.geodesy import CellMetric
    from orokit.topology.uncertainty import monte_carlo, prominence_bounds

    peaks = result.peaks
    low, high = prominence_bounds(peaks["prominence"].to_numpy(), peaks["saddle_row"].to_numpy() < 0, sigma_m, k)
    peaks["prominence_low"], peaks["prominence_high"] = low, high
    result.attrs.update({"dem_error_m": sigma_m, "error_k": k})
    if samples <= 0:
        return
    if tiled:
        raise InputError("the Monte Carlo of DEM error (samples > 0) runs in memory only; drop chunks "
                         "(--chunks) or run without --samples (the bounds need no samples)")
    if not (np.isfinite(corr_m) and corr_m >= 0):
        raise InputError(f"the error correlation length must be a length >= 0 (metres), got {corr_m!r}")
    if seed is None:
        entropy = np.random.SeedSequence().entropy
        assert isinstance(entropy, int)  # a fresh SeedSequence draws one int
        seed = entropy % 2**63
    cdx, cdy = CellMetric(transform, crs).cell_size_m(np.array([dem.shape[0] // 2]))
    dx, dy = float(np.asarray(cdx).ravel()[0]), float(np.asarray(cdy).ravel()[0])
    corr = (corr_m / dy, corr_m / dx)
    z = np.ascontiguousarray(np.asarray(dem.values, dtype=np.float64))
    mc = monte_carlo(z, core.peak_row, core.peak_col, sigma_m=sigma_m, corr_cells=corr, radius_cells=corr,
                     samples=samples, rng=np.random.default_rng(seed), min_prominence_m=min_prominence_m,
                     outside=outside, peak_prominence=core.prominence)
    peaks["p_exists"], peaks["prominence_median"] = mc.p_exists, mc.prominence_median
    result.attrs.update({"error_corr_m": corr_m, "samples": samples, "seed": int(seed),
                         "max_abs_error_m": float(mc.max_abs_error_m.max())})


def _depressions(dem, transform, crs, *, min_prominence_m, outside, sea_level_m, chunks, scheduler):
    """Depressions table: the engine on -h (see :mod:`orokit.topology.depressions`)."""
    import geopandas as gpd
    import rioxarray  # noqa: F401  (registers the .rio accessor: a DemArray input did not import it)
    import xarray as xr
    from affine import Affine

    from orokit.geodesy import CellMetric
    from orokit.topology.depressions import depressions_table, engine_grid, spill_areas

    t0 = time.perf_counter()
    data = dem.data
    g, sea, pad = engine_grid(data, outside=outside, sea_level_m=sea_level_m)
    t = transform
    gt = Affine(t.a, t.b, t.c - (t.a + t.b) * pad, t.d, t.e, t.f - (t.d + t.e) * pad)
    gda = xr.DataArray(g, dims=("y", "x"), attrs={"units": "m", "local_grid": crs is None,
                                                   **cell_size_attrs(t, crs)})
    gda = gda.rio.write_transform(gt)
    if crs is not None:
        gda = gda.rio.write_crs(crs)
    neg = analyze(gda, min_prominence_m=min_prominence_m, outside="unknown", isolation=False,
                  chunks=chunks, scheduler=scheduler)
    gv_rows = CellMetric(gt, crs).cell_size_m(np.arange(g.shape[0]))
    row_area = np.asarray(gv_rows[0] * gv_rows[1], np.float64) * np.ones(g.shape[0])
    p = neg.peaks
    if chunks is not None or hasattr(g, "dask"):
        from orokit.tiling.depression_area import tiled_spill_areas
        from orokit.tiling.engine import get_compute

        gd = g if hasattr(g, "dask") else _as_dask(g, chunks)
        if chunks is not None:
            gd = gd.rechunk(chunks)
        spill = np.where(p["island_parent"].to_numpy() < 0, np.nan, p["saddle_elevation"].to_numpy())
        client = None
        if isinstance(scheduler, str) and "://" in scheduler:  # one client for both passes, closed after
            from distributed import Client

            client = scheduler = Client(scheduler, set_as_default=False, timeout="20s")
        try:
            area = tiled_spill_areas(gd, p["row"].to_numpy(), p["col"].to_numpy(), p["elevation"].to_numpy(),
                                     spill, row_area, compute=get_compute(scheduler))
        finally:
            if client is not None:
                client.close()
    else:
        area = spill_areas(np.asarray(g, dtype=np.float64), p["row"].to_numpy(), p["col"].to_numpy(), row_area)
    table = depressions_table(neg.peaks, area_m2=area, sea=sea, pad=pad)
    logger.info("%d depressions with depth >= %g m in %.2f s", len(table), min_prominence_m,
                time.perf_counter() - t0)
    return gpd.GeoDataFrame(table, geometry=gpd.points_from_xy(table["x"], table["y"]), crs=crs)


def _table_libraries() -> None:
    """Import what the tables and their CSV/Parquet files need: pandas and pyarrow's writers.

    Not pyogrio (with shapely and geopandas, ~34 MB): imported here it sat beside the raster
    and raised the peak RSS at 15.1 M cells (397 -> 428 MB); the GeoPackage's thread imports it
    while the CSV is written.
    """
    import pandas  # noqa: F401
    import pyarrow.csv  # noqa: F401
    import pyarrow.parquet  # noqa: F401


def _import_in_thread(target):
    """Run ``target`` (imports) in a daemon thread; a failure is left to the later import that needs it."""
    import threading

    def run() -> None:
        try:
            target()
        except Exception:  # noqa: BLE001 - the import in the main thread raises it again, with its context
            logger.debug("background import failed", exc_info=True)

    thread = threading.Thread(target=run, name="orokit-imports", daemon=True)
    thread.start()
    return thread


def start_numba_target() -> None:
    """Start numba's CPU target as far as LLVM goes: its code generator and its runtime (NRT, which LLVM
    compiles at start), without the target's registries of implementations or any kernel.

    This step touches most of LLVM's code (~47 MiB of ``libllvmlite``'s pages after the import's
    were dropped, measured) in ~0.03 CPU s; the registries (numba's implementations, ~0.2 CPU s of
    Python with the array ones' import) touch none of it and load with the first kernel
    (:func:`load_kernels`: numba refreshes the target before loading a cached kernel). ``orokit
    analyze`` runs this, drops those pages, and only then reads the raster (issue 13: peak RSS), the
    registries loading beside the read instead of before it (its 2-core wall time).
    """
    from numba.core.registry import cpu_target
    from numba.core.runtime.nrt import rtsys

    rtsys.initialize(cpu_target.target_context)  # what the target's refresh does first (once per process)


def load_kernels(*, isolation: bool = True, strips_loaded: threading.Event | None = None) -> None:
    """Load the in-memory engine's compiled kernels (numba's cache) for float32 rasters, on tiny ones.

    The first call of each kernel loads it (~0.3 s of CPU in all, one thread);
    ``orokit analyze`` calls this while GDAL reads the DEM in other threads, which
    release the GIL. The tiny rasters cover both isolation searches (with and
    without nodata). Imports no pandas. The strips' kernels load first, then
    ``strips_loaded`` is set (on failure too): the saddle graph's strips may start
    while the other kernels load (numba loads a kernel under its compiler lock: one
    called meanwhile waits for it or loads it itself).
    """
    from affine import Affine

    from orokit.metrics.isolation import KernelMetric, nearest_higher
    from orokit.topology import engine

    try:
        engine.load_strip_kernels()
    finally:
        if strips_loaded is not None:
            strips_loaded.set()
    z = np.random.default_rng(0).random((8, 8)).astype(np.float32)
    core = engine.orometry(z, min_prominence_m=0.0)
    # the tree's kernels that the tables and the GeoPackage call (parents; the read-only
    # columns of the tree's frames are another type for numba): loaded now, not while writing
    from orokit.topology import _kernels

    rank, ea, eb = np.arange(3, dtype=np.int64), np.array([2, 1], np.int64), np.array([1, 0], np.int64)
    # the parents' sweep takes the ridges' ends in the narrowest index type (DivideTree.parents)
    line_parent, _ = _kernels.line_parents(rank, ea.astype(_kernels.index_like(3, 2).dtype),
                                           eb.astype(_kernels.index_like(3, 2).dtype))
    _kernels.first_ancestor_above(line_parent, np.zeros(3), rank)
    ea.flags.writeable = eb.flags.writeable = False
    _kernels.forest_components(3, ea, eb)
    # the finalize's sort on two threads (its merge: a tiny raster's edges are sorted whole)
    _kernels.merge_sorted_halves(np.array([2, 1], np.uint64), np.zeros(1, np.int64), np.zeros(1, np.int64), 1)
    if not isolation:
        return
    metric = KernelMetric.from_grid(Affine(1.0, 0.0, 0.0, 0.0, -1.0, 0.0), None)
    rows, cols = core.peak_row.astype(np.int64), core.peak_col.astype(np.int64)
    nearest_higher(z, rows, cols, metric)
    z[0, 0] = np.nan
    nearest_higher(z, rows, cols, metric)


#: bytes per cell the in-memory engine needs at most (measured: ~50 B/cell at 15 M cells)
BYTES_PER_CELL_IN_MEMORY = 64
#: chunk side used when a raster is too large for the in-memory engine
AUTO_CHUNK = 2048


def available_memory() -> int:
    """Available physical memory in bytes (psutil)."""
    import psutil

    return int(psutil.virtual_memory().available)


def plan_chunks(source: str | Path, *, memory_fraction: float = 0.5) -> int | None:
    """None (in memory) or a chunk size, from the raster's size and the free memory.

    A raster whose in-memory analysis would need more than ``memory_fraction`` of the
    available memory is analysed chunk by chunk (``AUTO_CHUNK`` cells per side); the
    plan is logged before any data is read.
    """
    from orokit.io.dem import raster_cell_count

    cells = raster_cell_count(source)
    if cells is None:
        return None
    need = cells * BYTES_PER_CELL_IN_MEMORY
    avail = available_memory()
    if need <= memory_fraction * avail:
        logger.info("%.1f M cells: in-memory engine (about %.1f GB of %.1f GB available)",
                    cells / 1e6, need / 1e9, avail / 1e9)
        return None
    logger.warning("%.1f M cells would need about %.1f GB in memory (%.1f GB available): analysing in "
                   "%d x %d chunks", cells / 1e6, need / 1e9, avail / 1e9, AUTO_CHUNK, AUTO_CHUNK)
    return AUTO_CHUNK


def _georef(dem):
    """Affine transform and CRS of a DataArray or DemArray (local grid when it has none)."""
    from affine import Affine

    from orokit.io.dem import DemArray

    if isinstance(dem, DemArray):
        return dem.transform, (None if dem.attrs.get("local_grid") else dem.crs)
    crs = None
    transform = None
    try:
        crs = dem.rio.crs
        transform = dem.rio.transform()
    except Exception:  # noqa: BLE001 - no rioxarray metadata at all
        pass
    if transform is None or transform == Affine.identity() and "x" not in dem.coords:
        cell = upgrade_attrs(dem.attrs, geographic=False).get("cell_size_m", 1.0)
        dx, dy = (float(cell[0]), float(cell[1])) if np.ndim(cell) else (float(cell), float(cell))
        transform = Affine(dx, 0.0, 0.0, 0.0, -dy, 0.0)
    if dem.attrs.get("local_grid"):
        crs = None
    return transform, crs


def _as_dask(data, chunks):
    import dask.array as da

    return da.from_array(data, chunks=chunks)


def _progress(enabled: bool, stages: list[str]):
    if not enabled:
        return None
    from tqdm.auto import tqdm

    return tqdm(total=len(stages), desc="analyze", unit="stage")


def _advance(bar) -> None:
    if bar is not None:
        bar.update(1)

