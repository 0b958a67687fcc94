"""Scaling benchmark of the chunked (dask) engine (issues 5 and 13).

Mosaics of n x n copies of a 648 x 648 real DEM (mirrored so seams are continuous):
the four mirror images are written once as GeoTIFF tiles and a VRT places them n * n
times, so nothing large is written (49 x 49: 1.0 G cells, 98 x 98: 4.0 G cells).
Each is analysed with ``orokit.analyze(read_dem(VRT, chunks=C), chunks=C, geometry=False, blocks=True)``
and written with ``orokit.write_analysis`` (what ``orokit analyze VRT -o OUT --chunks C`` does),
isolation on, in a fresh subprocess so its peak resident memory (all threads) is its own.
Prints M cells/s, peak RSS, the summed time of chunk tasks and of merge tasks, time per
cell against the in-memory run of the largest mosaic both handle, and (``--chunk-sweep``)
the merge cost against the number of chunks; chunked and in-memory peak and saddle
tables are compared for equality, and so are the threaded and the ``--workers``
(``dask.distributed`` LocalCluster) runs.

Run:  .venv/bin/python benchmarks/scaling.py [--sizes 6 12 49 98] [--chunks 2048]
          [--chunk-sweep 12 512 1024 2048] [--workdir /tmp/orokit-scaling]
          [--workers 2 --distributed-sizes 24]   # also on a 2-process LocalCluster: tables compared
          [--settled]   # settled peaks of every merge input: what streaming them would remove
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

FT = 0.3048


def write_mosaic(n: int, workdir: Path, dem_name: str) -> Path:
    """VRT of an n x n mosaic of a real DEM (mirrored, continuous seams); returns its path.

    Only the four mirror images of the DEM are written, as GeoTIFF tiles; the VRT
    places them n * n times, so a 4 G-cell mosaic needs ~7 MB of disk (plus the VRT).
    """
    import numpy as np
    import rasterio
    from affine import Affine

    from orokit.data import open_dataset_dem

    folder = workdir / f"tiles_{dem_name}"
    vrt = workdir / f"mosaic_{n}x{n}_{dem_name}.vrt"
    z = None
    res = 92.61
    paths = {}
    for fi in (0, 1):
        for fj in (0, 1):
            path = folder / f"tile_{fi}{fj}.tif"
            paths[fi, fj] = path
            if path.exists():
                continue
            if z is None:
                folder.mkdir(parents=True, exist_ok=True)
                z = open_dataset_dem(dem_name).values.astype("float32")
            t = z[:: (-1 if fi else 1), :: (-1 if fj else 1)]
            with rasterio.open(
                path, "w", driver="GTiff", width=t.shape[1], height=t.shape[0], count=1, dtype="float32",
                crs="EPSG:32645", transform=Affine(res, 0.0, 300000.0, 0.0, -res, 4000000.0),
                tiled=True, blockxsize=256, blockysize=256,
            ) as ds:
                ds.write(np.ascontiguousarray(t), 1)
                ds.set_band_unit(1, "m")
    if vrt.exists():
        return vrt
    with rasterio.open(paths[0, 0]) as ds:
        h, w = ds.height, ds.width
    sources = []
    for i in range(n):
        for j in range(n):
            sources.append(
                f'    <SimpleSource><SourceFilename relativeToVRT="0">{paths[i % 2, j % 2]}</SourceFilename>'
                f'<SourceBand>1</SourceBand><SrcRect xOff="0" yOff="0" xSize="{w}" ySize="{h}"/>'
                f'<DstRect xOff="{j * w}" yOff="{i * h}" xSize="{w}" ySize="{h}"/></SimpleSource>'
            )
    srs = "EPSG:32645"
    text = (
        f'<VRTDataset rasterXSize="{n * w}" rasterYSize="{n * h}">\n  <SRS>{srs}</SRS>\n'
        f'  <GeoTransform>300000.0, {res}, 0.0, 4000000.0, 0.0, {-res}</GeoTransform>\n'
        f'  <VRTRasterBand dataType="Float32" band="1">\n    <UnitType>m</UnitType>\n'
        + "\n".join(sources) + "\n  </VRTRasterBand>\n</VRTDataset>\n"
    )
    tmp = vrt.with_suffix(".vrt.tmp")
    tmp.write_text(text)
    tmp.replace(vrt)
    return vrt


class _PhaseRss:
    """Peak resident memory of each named phase of this process (Linux ``/proc``).

    At every phase change the kernel's high-water mark (``VmHWM``) is read as the peak of
    the phase that ends, then reset (``/proc/self/clear_refs`` 5), so a phase's peak is
    exact however short it is. A thread also samples ``VmRSS`` every ``interval``
    seconds; with ``log`` every sample is appended there as ``seconds<TAB>phase<TAB>MB``.
    """

    def __init__(self, interval: float = 0.5, log: str | None = None):
        import threading

        self.phase = "start"
        self.peak: dict[str, float] = {}
        self.interval = interval
        self.log = open(log, "w") if log else None  # noqa: SIM115 - closed in stop()
        self.t0 = time.perf_counter()
        self.lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    @staticmethod
    def status_mb(field: str) -> float:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith(field + ":"):
                    return int(line.split()[1]) / 1024.0
        return float("nan")

    def _note(self, phase: str, mb: float) -> None:
        self.peak[phase] = max(self.peak.get(phase, 0.0), mb)
        if self.log:
            self.log.write(f"{time.perf_counter() - self.t0:.1f}\t{phase}\t{mb:.0f}\n")
            self.log.flush()

    def _run(self) -> None:
        while not self._stop.wait(self.interval):
            with self.lock:
                self._note(self.phase, self.status_mb("VmRSS"))

    def enter(self, phase: str) -> None:
        with self.lock:
            self._note(self.phase, self.status_mb("VmHWM"))
            with open("/proc/self/clear_refs", "w") as f:
                f.write("5")  # reset VmHWM to the current RSS
            self.phase = phase

    def wrap(self, fn, phase: str):
        def wrapper(*a, **k):
            self.enter(phase)
            try:
                return fn(*a, **k)
            finally:
                self.enter("after " + phase)  # what follows it, e.g. freeing its inputs
        return wrapper

    def stop(self) -> dict[str, float]:
        self._stop.set()
        self._thread.join()
        self.enter("end")
        if self.log:
            self.log.close()
        return {k: round(v, 1) for k, v in self.peak.items() if k != "end"}


def _worker_peak_mb() -> float:
    """Peak resident memory of this (worker) process in MB."""
    return _PhaseRss.status_mb("VmHWM")


def _settled_hook(merge, eps: float, table: dict):
    """``merge_summaries`` that first counts the settled peaks of both inputs (tiling.summary.settled_peaks),
    by the input's size in cells: what streaming settled peaks out of the merges would remove."""
    import threading

    from orokit.tiling.summary import _side_mask, settled_peaks

    lock = threading.Lock()

    def wrapper(a, b, min_prominence_m, **kw):
        for s in (a, b):
            got = settled_peaks(s, eps)
            r0, r1, c0, c1 = s.region
            row = [1, s.n_nodes, int(s.ismax.sum()), int(_side_mask(s.key, s.region, s.shape).sum()),
                   int(got["cell"].size)]
            with lock:
                t = table.setdefault((r1 - r0) * (c1 - c0), [0] * len(row))
                table[(r1 - r0) * (c1 - c0)] = [x + y for x, y in zip(t, row)]
        return merge(a, b, min_prominence_m, **kw)
    return wrapper


def run_one(vrt: str, chunks: int | None, eps: float, out: str | None, rss_log: str | None = None,
            workers: int = 0, settled: bool = False, process_settings: bool = True) -> dict:
    """One measurement (in a subprocess): analyse, report time, peak RSS (per phase) and task costs.

    With ``workers`` > 0 the chunk tasks, merges and isolation reads run on a
    ``dask.distributed`` LocalCluster of that many single-threaded worker processes
    (started before the clock); their peak resident memory is reported per worker,
    and task costs are not timed (the tasks run in other processes).
    """
    import threading

    if process_settings:
        # the process of `orokit analyze` (its entry point's settings: two malloc arenas, blocks of 1 MB or
        # more mapped on their own, Arrow's system allocator, GDAL's cache bounded). Runs before session 16
        # set the GDAL cache only (--malloc-defaults): freed arrays of up to 32 MB stayed in the heap
        from orokit.cli.main import CHUNKED_MMAP_THRESHOLD_BYTES, apply_process_settings
        from orokit.tiling.memory import fix_mmap_threshold

        apply_process_settings("analyze")
        if chunks is not None:  # what `orokit analyze` sets once it takes the chunked engine
            fix_mmap_threshold(CHUNKED_MMAP_THRESHOLD_BYTES)
    else:
        from orokit.tiling.memory import limit_gdal_cache

        limit_gdal_cache()
    rss = _PhaseRss(log=rss_log)
    rss.enter("imports")
    import orokit
    from orokit.io.dem import read_dem
    from orokit.tiling import engine as tiling_engine
    from orokit.metrics import isolation as metrics_isolation
    from orokit.tiling import isolation as tiling_isolation
    from orokit.topology import engine as topo_engine

    cost = {"merge_s": 0.0, "merges": 0, "chunk_s": 0.0, "chunks": 0}
    lock = threading.Lock()

    def timed(fn, what):
        def wrapper(*a, **k):
            t = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                with lock:
                    cost[what + "_s"] += time.perf_counter() - t
                    cost[what + "s"] += 1
        return wrapper

    cluster = client = None
    if workers:
        import distributed

        cluster = distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                           dashboard_address=":0", memory_limit=0)
        client = distributed.Client(cluster)
    else:
        # the engine builds its graph from these module attributes: time every task
        tiling_engine.merge_summaries = timed(tiling_engine.merge_summaries, "merge")
        tiling_engine._tile_task = timed(tiling_engine._tile_task, "chunk")
    settled_table: dict = {}
    if settled:  # counted outside the timed merge: merge_s stays the merges' own cost
        tiling_engine.merge_summaries = _settled_hook(tiling_engine.merge_summaries, eps, settled_table)
    # phases: the chunk pass (chunk tasks + merges), isolation across chunks, tables, writing
    tiling_engine.tiled_orometry = rss.wrap(tiling_engine.tiled_orometry, "chunk pass")
    # inside the chunk pass, after the last merge: the root summary to peaks and Divide Tree
    tiling_engine.finalize_summary = rss.wrap(tiling_engine.finalize_summary, "finalize")
    tiling_isolation.tiled_isolation = rss.wrap(tiling_isolation.tiled_isolation, "isolation")
    # in memory, analyze runs engine.saddle_graph then finalize_graph, and nearest_higher for isolation
    topo_engine.saddle_graph = rss.wrap(topo_engine.saddle_graph, "engine (in memory)")
    metrics_isolation.nearest_higher = rss.wrap(metrics_isolation.nearest_higher, "isolation")
    topo_engine.build_result = rss.wrap(topo_engine.build_result, "tables")
    import logging

    class _Keep(logging.Handler):  # the engine's own counts (chunk loads of the isolation search)
        def __init__(self):
            super().__init__(logging.INFO)
            self.lines: list[str] = []

        def emit(self, record):
            self.lines.append(record.getMessage())

    keep = _Keep()
    for name in ("orokit.tiling.engine", "orokit.tiling.isolation"):
        logging.getLogger(name).addHandler(keep)
        logging.getLogger(name).setLevel(logging.INFO)
    rss.enter("read")
    t0 = time.perf_counter()
    dem = read_dem(vrt, chunks=chunks)
    # as `orokit analyze VRT -o OUT --chunks N`: the peaks table made by blocks of rows as it is written
    r = orokit.analyze(dem, min_prominence_m=eps, chunks=chunks, geometry=False, blocks=True, scheduler=client)
    t_analyze = time.perf_counter() - t0
    rss.enter("before writing")
    rss_analyze = max(rss.peak.values())
    cells = int(dem.shape[0] * dem.shape[1])
    del dem
    if out:
        rss.enter("writing")
        orokit.write_analysis(r, out, overwrite=True)
    dt = time.perf_counter() - t0
    ru = resource.getrusage(resource.RUSAGE_SELF)
    by_phase = rss.stop()
    worker_mb = None
    if client is not None:
        worker_mb = sorted(round(v, 1) for v in client.run(_worker_peak_mb).values())
        client.close()
        cluster.close()
    return {
        "cells": cells,
        "seconds": dt,
        "seconds_write": dt - t_analyze,
        # CPU seconds of this process since it started (all threads; imports included)
        "cpu_s": ru.ru_utime + ru.ru_stime,
        "peaks": int(len(r.peaks)),
        "timings": r.attrs["timings_s"],
        "task_costs": cost,
        # the phases cover the whole run: their largest peak is the process's (ru_maxrss is reset with them)
        "rss_mb": max(by_phase.values()),
        "rss_mb_before_writing": rss_analyze,
        "rss_mb_by_phase": by_phase,
        "load_average_1min": os.getloadavg()[0],
        "engine_log": keep.lines,
        "workers": workers,
        "worker_rss_mb": worker_mb,
        # per merge-input size in cells: [inputs, nodes, maxima, side nodes, settled maxima]
        **({"settled_by_region_cells": {str(k): v for k, v in sorted(settled_table.items())}} if settled else {}),
    }


def measure(vrt: Path, chunks: int | None, eps: float, out: Path | None = None, rss_log: Path | None = None,
            workers: int = 0, settled: bool = False, process_settings: bool = True) -> dict:
    """:func:`run_one` in a fresh subprocess."""
    cmd = [sys.executable, __file__, "--one", str(vrt), "--eps", str(eps), "--workers", str(workers)]
    if not process_settings:
        cmd += ["--malloc-defaults"]
    if settled:
        cmd += ["--settled"]
    if rss_log:
        cmd += ["--rss-log", str(rss_log)]
    if chunks:
        cmd += ["--chunks", str(chunks)]
    if out:
        cmd += ["--out", str(out)]
    res = subprocess.run(cmd, capture_output=True, text=True, check=True)
    return json.loads(res.stdout.strip().splitlines()[-1])


def _same_tables(a: Path, b: Path) -> bool:
    """peaks.parquet and saddles.parquet of two analysis folders hold equal tables."""
    import pandas as pd

    return all(pd.read_parquet(a / f).equals(pd.read_parquet(b / f)) for f in ("peaks.parquet", "saddles.parquet"))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[6, 12, 49],
                    help="mosaics of n x n DEMs (49: 1.0 G cells, 98: 4.0 G cells)")
    ap.add_argument("--chunks", type=int, default=1024)
    ap.add_argument("--eps-ft", type=float, default=100.0)
    ap.add_argument("--dem", default="karakoram")
    ap.add_argument("--workdir", type=Path, default=Path("/tmp/orokit-scaling"))
    ap.add_argument("--in-memory-max", type=int, default=12, help="largest mosaic also run in memory")
    ap.add_argument("--chunk-sweep", type=int, nargs="+", default=None, metavar="N CHUNK",
                    help="mosaic size N then chunk sizes: merge cost against the number of chunks")
    ap.add_argument("--one")
    ap.add_argument("--eps", type=float)
    ap.add_argument("--out")
    ap.add_argument("--workers", type=int, default=0,
                    help="also run each chunked mosaic on a dask.distributed LocalCluster of this many worker "
                         "processes (one thread each) and compare its tables with the threaded run")
    ap.add_argument("--distributed-sizes", type=int, nargs="+", metavar="N",
                    help="with --workers: only these mosaics run on the cluster (default: all)")
    ap.add_argument("--rss-log", help="(with --one) append every resident-memory sample here: seconds phase MB")
    ap.add_argument("--malloc-defaults", action="store_true",
                    help="measure without `orokit analyze`'s process settings (glibc's malloc defaults, as every run "
                         "before session 16): GDAL's cache bounded only")
    ap.add_argument("--settled", action="store_true",
                    help="count the settled peaks of every merge input (what streaming them out would remove; "
                         "adds the count's cost to the run, not to the merge tasks' time)")
    args = ap.parse_args()
    if args.one:
        print(json.dumps(run_one(args.one, args.chunks if "--chunks" in sys.argv else None, args.eps, args.out,
                                 args.rss_log, args.workers, args.settled, not args.malloc_defaults)))
        return

    import pandas as pd

    eps = args.eps_ft * FT
    print(f"chunked engine, chunks {args.chunks}^2, eps {args.eps_ft:g} ft, {os.cpu_count()} cores; "
          f"GeoTIFF tiles + VRT read lazily")
    print(f"{'mosaic':>8} {'M cells':>8} {'mode':>10} {'peaks':>8} {'seconds':>8} {'Mc/s':>6} {'peak RSS MB':>11} "
          f"{'chunks':>6} {'chunk s':>8} {'merges':>6} {'merge s':>8} {'load':>5}")
    print("(chunk s / merge s: summed task seconds over all threads)")
    rows = {}
    for n in args.sizes:
        vrt = write_mosaic(n, args.workdir, args.dem)
        modes = [("chunked", args.chunks)] + ([("in-memory", None)] if n <= args.in_memory_max else [])
        modes += [("distributed", args.chunks)] if args.workers and n in (args.distributed_sizes or args.sizes) else []
        for mode, ch in modes:
            out = args.workdir / f"analysis_{n}_{mode}"
            m = measure(vrt, ch, eps, out, rss_log=args.workdir / f"rss_{n}_{mode}.log",
                        workers=args.workers if mode == "distributed" else 0,
                        settled=args.settled and mode == "chunked", process_settings=not args.malloc_defaults)
            rows[n, mode] = m
            (args.workdir / f"run_{n}_{mode}.json").write_text(json.dumps(m))  # kept if a later size is stopped
            tc = m["task_costs"]
            merge = (f"{tc['chunks']:>6d} {tc['chunk_s']:>8.1f} {tc['merges']:>6d} {tc['merge_s']:>8.1f}"
                     if tc["chunks"] else f"{'':>6} {'':>8} {'':>6} {'':>8}")
            print(f"{n:>3}x{n:<4} {m['cells'] / 1e6:>8.1f} {mode:>10} {m['peaks']:>8d} {m['seconds']:>8.1f} "
                  f"{m['cells'] / m['seconds'] / 1e6:>6.1f} {m['rss_mb']:>11.0f} {merge} {m['load_average_1min']:>5.1f}"
                  f"  ({m['cpu_s']:.0f} CPU s)")
            print("         peak RSS MB by phase: " + ", ".join(f"{k} {v:.0f}" for k, v in m["rss_mb_by_phase"].items()))
            if "settled_by_region_cells" in m:
                print("         merge inputs by size: M cells, inputs, nodes, maxima, side nodes, settled maxima "
                      "(share of the nodes)")
                for cells, (k, nodes, mx, side, st) in m["settled_by_region_cells"].items():
                    print(f"         {int(cells) / 1e6:>9.1f} {k:>5} {nodes:>9} {mx:>9} {side:>8} {st:>9} "
                          f"({st / max(nodes, 1):.1%})")
            if mode == "distributed":
                same = _same_tables(args.workdir / f"analysis_{n}_chunked", out)
                m["tables_identical_to_threaded"] = same
                print(f"         {args.workers} worker processes, peak RSS MB each: {m['worker_rss_mb']} "
                      f"(the client process: {m['rss_mb']:.0f}); peaks and saddles identical to the threaded run: "
                      f"{same}")
    summary = {"chunks": args.chunks, "eps_ft": args.eps_ft, "dem": args.dem,
               "process_settings": "malloc defaults" if args.malloc_defaults else "orokit analyze's",
               "runs": [{"mosaic": n, "mode": mode, **m} for (n, mode), m in rows.items()]}
    both = [n for n in args.sizes if (n, "in-memory") in rows]
    if both:
        n = max(both)
        c, i = rows[n, "chunked"], rows[n, "in-memory"]
        same = _same_tables(args.workdir / f"analysis_{n}_chunked", args.workdir / f"analysis_{n}_in-memory")
        print(f"largest raster both handle ({n}x{n}, {c['cells'] / 1e6:.1f} M cells): chunked/in-memory time "
              f"{c['seconds'] / i['seconds']:.2f}x, memory {c['rss_mb'] / i['rss_mb']:.2f}x; "
              f"peak and saddle tables identical: {same}")
        summary.update({"time_ratio_chunked_vs_in_memory": c["seconds"] / i["seconds"],
                        "memory_ratio_chunked_vs_in_memory": c["rss_mb"] / i["rss_mb"],
                        "tables_identical": same})
    if both:
        base = rows[max(both), "in-memory"]
        per_cell = base["seconds"] / base["cells"]
        for n in args.sizes:
            c = rows[n, "chunked"]
            ratio = (c["seconds"] / c["cells"]) / per_cell
            cpu_ratio = (c["cpu_s"] / c["cells"]) / (base["cpu_s"] / base["cells"])
            print(f"{n}x{n} chunked: time per cell {ratio:.2f}x the in-memory {max(both)}x{max(both)} run "
                  f"(target <= 1.3; CPU per cell {cpu_ratio:.2f}x), peak RSS {c['rss_mb'] / 1024:.2f} GB (target < 2)")
            c["time_per_cell_vs_in_memory"] = ratio
            c["cpu_per_cell_vs_in_memory"] = cpu_ratio
    if args.chunk_sweep:
        n = args.chunk_sweep[0]
        vrt = write_mosaic(n, args.workdir, args.dem)
        print(f"merge cost against the number of chunks ({n}x{n} mosaic):")
        print(f"{'chunk':>6} {'chunks':>6} {'merges':>6} {'merge s':>8} {'chunk s':>8} {'total s':>8} {'RSS MB':>7}")
        sweep = []
        for ch in args.chunk_sweep[1:]:
            m = measure(vrt, ch, eps, process_settings=not args.malloc_defaults)
            tc = m["task_costs"]
            print(f"{ch:>6} {tc['chunks']:>6} {tc['merges']:>6} {tc['merge_s']:>8.2f} {tc['chunk_s']:>8.2f} "
                  f"{m['seconds']:>8.1f} {m['rss_mb']:>7.0f}")
            sweep.append({"chunk": ch, **m})
        summary["chunk_sweep"] = {"mosaic": n, "runs": sweep}
    sizes = sorted(n for n in args.sizes)
    if len(sizes) > 1:
        s0, s1 = rows[sizes[0], "chunked"], rows[sizes[-1], "chunked"]
        print(f"time per cell, largest vs smallest chunked run: "
              f"{(s1['seconds'] / s1['cells']) / (s0['seconds'] / s0['cells']):.2f} (1.0 = linear in area)")
    sys.path.insert(0, str(Path(__file__).parent))
    from _record import record

    print(f"recorded in {record('scaling', summary)}")


if __name__ == "__main__":
    main()
