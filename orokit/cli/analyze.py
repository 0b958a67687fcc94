"""``orokit analyze``: peaks, prominence, isolation and the Divide Tree of one DEM."""
from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import click

from orokit.cli.options import (
    INPUT,
    InputSource,
    Length,
    cell_size_option,
    min_prominence_option,
    overwrite_option,
    progress_option,
    seed_option,
    z_units_option,
)

if TYPE_CHECKING:
    from concurrent.futures import Future, ThreadPoolExecutor

#: a DEM error or correlation length: 0 allowed
_ERROR_LENGTH = Length(allow_bare=True, allow_zero=True)
#: smallest ``--chunks`` (cells on a side): each chunk costs ~10 ms CPU whatever its size (its window's dask
#: graph and reads, its task, summary and merge; session 17, load 11-15: 100 x 100 cells took 3.6 s CPU with
#: 16-cell chunks, 8.3 s with 4, 30 s with 2), and a window's read grows with the number of chunks
MIN_CHUNK_SIDE = 16
#: rasters of more cells are read beside numba's start (its import and target, ~0.25 CPU s of Python that
#: otherwise leaves a core idle: 2-core start + read modelled 1.19 -> 0.99 s at 60.5 M cells, load 12-15);
#: smaller ones after it, once LLVM's pages (~47 MiB) are dropped: beside a small raster they were the
#: process's peak (15.1 M cells, session 15). Beside a large one they are below the saddle graph's peak
#: that follows on real terrain (with isolation: 34 M cells read 288 against 312 MiB, 60.5 M 386 against
#: 478-485), but not on a raster with almost no relief (41 M smooth cells without isolation: peak 285 -> 300-314 MiB)
READ_BESIDE_TARGET_CELLS = 1 << 25


@click.command()
@click.argument("dem", type=INPUT)
@click.option("-o", "--output", "outdir", required=True, type=click.Path(file_okay=False, path_type=Path),
              help="Output folder: peaks.csv, peaks.parquet, saddles.parquet, dividetree.gpkg, analysis.json.")
@min_prominence_option(help="Keep peaks with prominence >= this")
@z_units_option()
@cell_size_option()
@click.option("--band", type=int, default=None, help="Band number (1-based) of a multi-band raster.")
@click.option("--outside", type=click.Choice(["unknown", "sea"]), default="unknown", show_default=True,
              help="What lies beyond the data edge and nodata: unknown (edge prominences flagged as upper "
                   "bounds) or sea (all exact).")
@click.option("--no-isolation", is_flag=True, help="Skip the isolation search.")
@click.option("--chunks", type=int, default=None,
              help="Analyse chunk by chunk (out of core) with chunks of N x N cells (N >= 16); exact, same results.")
@click.option("--scheduler", default=None,
              help="dask scheduler for --chunks: threads (default), processes, synchronous, or the address "
                   "of a dask.distributed scheduler (tcp://host:8786).")
@click.option("--checkpoint", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Folder for chunk summaries; rerunning with it reuses the finished chunks.")
@overwrite_option("an existing analysis in OUTPUT")
@progress_option()
@click.option("--depressions", is_flag=True,
              help="Also find the depressions (pits) with depth >= the threshold: depressions.parquet and a "
                   "'depressions' layer in dividetree.gpkg.")
@click.option("--sea-level", "sea_level_m", type=float, default=None,
              help="With --depressions: cells at or below this elevation (metres) are one sea.")
@click.option("--dem-error", "dem_error_m", type=_ERROR_LENGTH, default=None,
              help="Standard deviation sigma of the DEM error (a length: 5m, 16ft; a plain number is metres): "
                   "adds prominence_low/prominence_high, guaranteed for any error of at most k x sigma.")
@click.option("--error-k", type=click.FloatRange(min=0, min_open=True), default=2.0, show_default=True,
              help="With --dem-error: the bounds hold for errors of at most this many sigma.")
@click.option("--error-corr", "error_corr_m", type=_ERROR_LENGTH, default="0", show_default=True,
              help="With --samples: correlation length of the simulated error (a length; 0 = white noise).")
@click.option("--samples", type=click.IntRange(min=0), default=0, show_default=True,
              help="With --dem-error: Monte Carlo realisations of the error (in memory), adding p_exists and "
                   "prominence_median.")
@seed_option(what="the DEM-error Monte Carlo", default=None, recorded_in="analysis.json")
@click.pass_context
def analyze(ctx: click.Context, dem: InputSource, outdir: Path, min_prominence_m: float, z_units: str | None, cell_size_m: float | None,
            band: int | None, outside: Literal["unknown", "sea"], no_isolation: bool, chunks: int | None, scheduler: str | None,
            checkpoint: Path | None, overwrite: bool, progress: bool, depressions: bool,
            sea_level_m: float | None, dem_error_m: float | None, error_k: float, error_corr_m: float,
            samples: int, seed: int | None) -> None:
    """Analyse DEM into OUTPUT.

    DEM is any raster GDAL reads (GeoTIFF, SRTM .hgt, VRT, ASCII grid, PNG with
    --z-units and --cell-size), a directory of tiles, or the name of a DEM of the
    datasets manifest (`orokit data list`; units and cell size come from it).
    Row/col are 0-based on the input grid with row 0 at the top; all elevations,
    prominences and distances are in metres.
    """
    from orokit.cli.outputs import claim_outputs
    from orokit.io.analysis_io import ANALYSIS_FILES

    claim_outputs(outdir, names=ANALYSIS_FILES)  # locked for the whole run
    if (outdir / "analysis.json").exists() and not overwrite:
        raise click.UsageError(f"{outdir} already holds an analysis; pass --overwrite to replace it")
    t0 = time.perf_counter()
    if chunks is not None and chunks < MIN_CHUNK_SIDE:
        raise click.BadParameter(
            f"must be at least {MIN_CHUNK_SIDE}, got {chunks}: N is the side of each chunk in cells (chunks of N x N "
            "cells), not a number of chunks, and every chunk costs a fixed ~10 ms (1 x 1 chunks take minutes where "
            "the whole raster in memory takes seconds). Give e.g. --chunks 1024, or leave --chunks out: a DEM too "
            "large for memory is then analysed in chunks of a size chosen for it", param_hint="--chunks")
    if chunks is not None:
        chunks = min(chunks, 1 << 31)  # one chunk per side beyond the raster's (dask took 1e20 for no integer)
    if samples and dem_error_m is None:
        raise click.UsageError("--samples needs --dem-error SIGMA")
    if samples and chunks is not None:
        raise click.UsageError("--samples (the Monte Carlo) runs in memory: drop --chunks")
    if (scheduler or checkpoint) and chunks is None:
        raise click.UsageError("--scheduler and --checkpoint need --chunks N")
    if chunks is None and not dem.path.is_dir():  # a manifest DEM's file too (it was read whole whatever its size)
        from orokit.analysis import plan_chunks

        chunks = plan_chunks(str(dem.path))
        if chunks is not None:
            click.echo(f"{dem.path} is too large for memory: analysing in {chunks} x {chunks} chunks", err=True)
    loader: tuple[ThreadPoolExecutor, Future[None]] | None = None  # the kernels' loader, beside the engine
    if chunks is None and dem.dataset is None:
        from concurrent.futures import ThreadPoolExecutor

        from orokit.cli.main import owns_process
        from orokit.tiling.memory import GDAL_WHOLE_READ_CACHE_BYTES, limit_gdal_cache, release_library_pages

        # in memory: plain numpy (no xarray/rioxarray/dask imports: faster start, less memory); a
        # second thread imports numba and loads the kernels while GDAL reads (wall time). The read
        # stays in this thread: its freed buffers are reused later (a reader thread's malloc arena
        # kept ~70 MB more resident at 15 M cells). In orokit's own process the read waits for
        # numba's target to start as far as LLVM goes, then the pages of files touched so far are
        # dropped (LLVM's, ~47-65 MB at 15 M cells, the imports'): resident with the raster they were
        # the process's peak. numba's implementations (~0.2 CPU s of Python) load beside the read
        # (a raster of more than READ_BESIDE_TARGET_CELLS cells is read beside numba's start as well)
        started = threading.Event() if owns_process() else None
        strips_loaded = threading.Event()
        pool = ThreadPoolExecutor(1)
        loading = pool.submit(_load_kernels, isolation=not no_isolation, started=started, strips_loaded=strips_loaded)
        large = False
        try:
            from orokit.io.dem import raster_cell_count, read_dem_array

            if started is not None:
                limit_gdal_cache(GDAL_WHOLE_READ_CACHE_BYTES)  # a whole read (unless the user set it)
                large = (raster_cell_count(str(dem.path)) or 0) > READ_BESIDE_TARGET_CELLS
                if not large:
                    started.wait()  # set by the loader in any case
                    release_library_pages("")
            da = read_dem_array(str(dem.path), z_units=z_units, cell_size_m=cell_size_m, band=band)
        except BaseException:
            pool.shutdown()  # the loader done, the read's error is raised
            raise
        # the kernels are loaded: LLVM's code (~65 MB resident at 15 M cells) is not needed until a
        # kernel compiles again, nor the reader's and the imports' code: the pages of every file go
        # back to the page cache before the engine's peak (what the engine runs comes back). Only in
        # orokit's own process: a caller's (a CliRunner test, a script) may be compiling meanwhile. A
        # large raster's engine starts once the strips' kernels are loaded, the others loading beside
        # its strips (the loader drops LLVM's pages it touched then): the loader's 0.1-0.4 CPU s after
        # the read left a core idle (60.5 M cells, load 11-14)
        if large:
            strips_loaded.wait()  # set by the loader in any case
            loader = (pool, loading)
        else:
            pool.shutdown()
            loading.result()
        if owns_process():
            release_library_pages("")
    else:
        from orokit.cli.main import CHUNKED_MMAP_THRESHOLD_BYTES, owns_process

        # a chunked run reuses its per-batch arrays from the heap (CHUNKED_MMAP_THRESHOLD_BYTES); a manifest
        # DEM read whole (a dataset name without --chunks) comes here too and keeps the in-memory 1 MB
        if owns_process() and chunks is not None:
            from orokit.tiling.memory import fix_mmap_threshold

            fix_mmap_threshold(CHUNKED_MMAP_THRESHOLD_BYTES)
        _numba_without_blas_probe()
        da = dem.read_dem(z_units=z_units, cell_size_m=cell_size_m, chunks=chunks, band=band)
    from orokit.analysis import analyze as run

    try:
        result = run(da, min_prominence_m=min_prominence_m, outside=outside, isolation=not no_isolation,
                     progress=progress, chunks=chunks, scheduler=scheduler, checkpoint=checkpoint,
                     depressions=depressions, sea_level_m=sea_level_m, dem_error_m=dem_error_m, error_k=error_k,
                     error_corr_m=error_corr_m, samples=samples, seed=seed, geometry=False,
                     blocks=True, release_dem=True)
    finally:
        if loader is not None:
            loader[0].shutdown()
    if loader is not None:
        loader[1].result()
    from orokit.io.analysis_io import write_analysis

    shape = da.shape
    del da  # the raster is not needed to write the tables: lower peak memory
    from orokit.tiling.memory import release_free_heap

    release_free_heap()  # what the engine and isolation freed inside the heap, before the writers' libraries
    from orokit.cli.main import owns_process

    if owns_process():  # the code of the read, the engine and the imports is done: the writers' comes back
        import sys

        from orokit.cli.main import WRITING_SWITCH_INTERVAL_S
        from orokit.tiling.memory import release_library_pages

        release_library_pages("")
        sys.setswitchinterval(WRITING_SWITCH_INTERVAL_S)
    write_analysis(result, outdir, overwrite=True)
    n = len(result.peaks)
    if (ctx.find_root().obj or {}).get("quiet"):
        return
    click.echo(
        f"{n} peaks with prominence >= {min_prominence_m:g} m, {len(result.saddles)} saddles, "
        f"{shape[0]}x{shape[1]} cells in {time.perf_counter() - t0:.2f} s -> {outdir}"
        + ("" if result.depressions is None else f" ({len(result.depressions)} depressions)")
    )


def _load_kernels(*, isolation: bool, started: threading.Event | None = None,
                  strips_loaded: threading.Event | None = None) -> None:
    """Import numba and load the engine's kernels, ``strips_loaded`` set once the strips' are (on failure
    too). With ``started`` (orokit's own process): first start numba's target as far as LLVM goes (most of
    LLVM's pages), then set ``started`` (set on failure too), then load numba's implementations and the
    kernels (beside the read); the pages of files are dropped before the target starts (the imports
    touched them) and LLVM's after the loading."""
    try:
        try:
            from orokit.analysis import load_kernels, start_numba_target
            from orokit.tiling.memory import release_library_pages

            if started is not None:
                import numba  # noqa: F401 - LLVM's library, before its pages are dropped

                release_library_pages("")  # the imports' pages (LLVM's first 36 MB): not all touched again
                start_numba_target()
        finally:
            if started is not None:
                started.set()
        _numba_without_blas_probe()  # before the target's implementations load (with the first kernel)
        load_kernels(isolation=isolation, strips_loaded=strips_loaded)  # sets it once the strips' are loaded
    finally:
        if strips_loaded is not None:
            strips_loaded.set()  # on failure too: the main thread waits for neither event in vain
    if started is not None:
        release_library_pages("libllvmlite")  # what the loading touched (12 MB), if the read is not done


def _numba_without_blas_probe() -> None:
    """Load numba's array implementations without importing scipy.linalg for its BLAS probe.

    numba imports ``scipy.linalg.cython_blas`` when its CPU target starts, only to offer
    ``np.dot``/``np.linalg`` in compiled code; no orokit kernel uses them, and the probe
    costs ~0.12 s of CPU and ~15 MB in every ``orokit analyze`` process (measured). While
    the implementations load, ``scipy.linalg`` is marked unimportable; it is importable
    again right after (numba then simply has no BLAS in this process). A process that
    already imported either is left as it is.
    """
    import sys

    if "scipy.linalg" in sys.modules or "numba.np.arraymath" in sys.modules:
        return
    sys.modules["scipy.linalg"] = None  # type: ignore[assignment]  # import raises ImportError
    try:
        import numba.np.arraymath  # noqa: F401
    finally:
        if sys.modules.get("scipy.linalg", 0) is None:
            del sys.modules["scipy.linalg"]
