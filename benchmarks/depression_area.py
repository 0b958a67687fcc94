"""Memory and exactness of the chunked depression-area pass (issue 16).

Mosaics of n x n mirrored copies of a real DEM (``benchmarks/scaling.py``: a VRT over
four GeoTIFF tiles) are analysed with ``analyze(read_dem(VRT, chunks=C), chunks=C,
depressions=True, isolation=False)`` in a fresh subprocess each. Records the wall
time of the whole analysis and of the area pass (:func:`orokit.tiling.depression_area.
tiled_spill_areas`), the process RSS just before the area pass and its maximum during
the pass (psutil, sampled every 50 ms), the process peak RSS, and the load average.
Mosaics up to ``--in-memory-max`` are also analysed in memory and the two
``area_m2`` columns compared (largest relative difference; the other columns must be
identical).

Run:  nice .venv/bin/python benchmarks/depression_area.py [--sizes 8 16] [--chunks 2048]
          [--in-memory-max 8] [--json reports/benchmarks/depression_area.json]
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from scaling import FT, write_mosaic  # noqa: E402


def run_one(vrt: str, chunks: int | None, eps: float, out: str) -> dict:
    """One analysis with depressions (in a subprocess); the table is written to ``out``."""
    import psutil

    from orokit.tiling.memory import limit_gdal_cache

    limit_gdal_cache()  # as `orokit analyze` (its entry point's setting since session 14; the library's before)
    import orokit
    from orokit.io.dem import read_dem
    from orokit.tiling import depression_area

    proc = psutil.Process()
    stats: dict = {}
    inner = depression_area.tiled_spill_areas

    def watched(*a, **k):
        stats["rss_before_mb"] = proc.memory_info().rss / 2**20
        peak = [stats["rss_before_mb"]]
        done = threading.Event()

        def sample():
            while not done.wait(0.05):
                peak[0] = max(peak[0], proc.memory_info().rss / 2**20)

        th = threading.Thread(target=sample, daemon=True)
        th.start()
        t = time.perf_counter()
        try:
            return inner(*a, **k)
        finally:
            stats["area_pass_s"] = time.perf_counter() - t
            done.set()
            th.join()
            stats["rss_max_during_pass_mb"] = max(peak[0], proc.memory_info().rss / 2**20)
            stats["load_average_1min_after_pass"] = os.getloadavg()[0]

    depression_area.tiled_spill_areas = watched
    t0 = time.perf_counter()
    dem = read_dem(vrt, chunks=chunks)
    r = orokit.analyze(dem, min_prominence_m=eps, chunks=chunks, depressions=True, isolation=False)
    dt = time.perf_counter() - t0
    r.depressions.drop(columns="geometry").to_parquet(out)
    return {"cells": int(dem.shape[0] * dem.shape[1]), "chunks": chunks, "seconds": dt,
            "depressions": int(len(r.depressions)), **stats,
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
            "load_average_1min": os.getloadavg()[0]}


def measure(vrt: Path, chunks: int | None, eps: float, out: Path) -> dict:
    cmd = [sys.executable, __file__, "--one", str(vrt), "--eps", str(eps), "--out", str(out)]
    if chunks:
        cmd += ["--chunks", str(chunks)]
    res = subprocess.run(cmd, capture_output=True, text=True, check=True)
    return json.loads(res.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[8, 16])
    ap.add_argument("--chunks", type=int, default=2048)
    ap.add_argument("--eps-ft", type=float, default=100.0)
    ap.add_argument("--dem", default="karakoram")
    ap.add_argument("--workdir", type=Path, default=Path("/tmp/orokit-scaling"))
    ap.add_argument("--in-memory-max", type=int, default=8)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--one")
    ap.add_argument("--eps", type=float)
    ap.add_argument("--out")
    args = ap.parse_args()
    if args.one:
        print(json.dumps(run_one(args.one, args.chunks if "--chunks" in sys.argv else None, args.eps, args.out)))
        return
    import numpy as np
    import pandas as pd

    args.workdir.mkdir(parents=True, exist_ok=True)
    eps = args.eps_ft * FT
    rows = []
    for n in args.sizes:
        vrt = write_mosaic(n, args.workdir, args.dem)
        out_c = args.workdir / f"dep_{n}_chunked.parquet"
        m = measure(vrt, args.chunks, eps, out_c)
        m["mosaic"] = n
        if n <= args.in_memory_max:
            out_m = args.workdir / f"dep_{n}_memory.parquet"
            mm = measure(vrt, None, eps, out_m)
            a, b = pd.read_parquet(out_m), pd.read_parquet(out_c)
            cols = [c for c in a.columns if c != "area_m2"]
            x, y = a["area_m2"].to_numpy(), b["area_m2"].to_numpy()
            fin = np.isfinite(x)
            m.update({"in_memory_seconds": mm["seconds"], "in_memory_peak_rss_mb": mm["peak_rss_mb"],
                      "other_columns_identical": bool(a[cols].equals(b[cols])),
                      "nan_pattern_identical": bool(np.array_equal(fin, np.isfinite(y))),
                      "area_max_rel_diff": float(np.max(np.abs(y[fin] - x[fin]) / np.maximum(x[fin], 1e-300)))
                      if fin.any() else 0.0,
                      "area_max_abs_diff_m2": float(np.max(np.abs(y[fin] - x[fin]))) if fin.any() else 0.0,
                      "areas_compared": int(fin.sum())})
        rows.append(m)
        print(json.dumps(m), flush=True)
    if args.json:
        rec = {"benchmark": "depression_area", "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
               "command": " ".join(sys.argv), "dem": args.dem, "eps_ft": args.eps_ft, "runs": rows}
        args.json.write_text(json.dumps(rec, indent=1) + "\n")


if __name__ == "__main__":
    main()
