"""Scaling benchmark of the chunked (dask) engine (issue 5).

Mosaics of the 648 x 648 real DEMs (mirrored so seams are continuous) of n x n tiles,
written as one GeoTIFF per tile plus a VRT, analysed with ``orokit.analyze(...,
chunks=C)`` reading the VRT lazily. Every measurement runs in a fresh subprocess
so its peak resident memory (all threads) is its own. Prints M cells/s, peak RSS,
and the time and memory ratio of chunked vs in-memory on the largest raster both
handle; the chunked and in-memory peak tables are compared for equality.

Reference on this machine (issue 5): Kirmse's C++ program, 60 M cells in 22.8 s
single-threaded with 850 MB as one tile.

Run:  .venv/bin/python benchmarks/scaling.py [--sizes 6 12 24] [--chunks 2048] [--workdir /tmp/orokit-scaling]
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
    """n x n GeoTIFF tiles + VRT; returns the VRT path (reused when present)."""
    import numpy as np
    import rasterio
    from rasterio.transform import from_origin

    from orokit.data import open_dataset_dem
    from orokit.io.mosaic import build_vrt

    folder = workdir / f"mosaic_{n}x{n}_{dem_name}"
    vrt = folder / "mosaic.vrt"
    if vrt.exists():
        return vrt
    folder.mkdir(parents=True, exist_ok=True)
    z = open_dataset_dem(dem_name).values.astype("float32")
    h, w = z.shape
    res = 92.61
    for i in range(n):
        for j in range(n):
            t = z[:: (1 if i % 2 == 0 else -1), :: (1 if j % 2 == 0 else -1)]
            with rasterio.open(
                folder / f"tile_{i:03d}_{j:03d}.tif", "w", driver="GTiff", width=w, height=h, count=1,
                dtype="float32", crs="EPSG:32645", transform=from_origin(300000 + j * w * res, 4000000 - i * h * res, res, res),
                tiled=True, blockxsize=256, blockysize=256,
            ) as ds:
                ds.write(np.ascontiguousarray(t), 1)
    return build_vrt(sorted(folder.glob("tile_*.tif")), vrt)


def run_one(vrt: str, chunks: int | None, eps: float, out: str | None) -> dict:
    """One measurement (in a subprocess): analyse, report time and peak RSS."""
    import orokit
    from orokit.io.dem import read_dem

    t0 = time.perf_counter()
    dem = read_dem(vrt, chunks=chunks)
    r = orokit.analyze(dem, min_prominence=eps, chunks=chunks)
    dt = time.perf_counter() - t0
    if out:
        r.peaks.drop(columns="geometry").to_parquet(out)
    return {
        "cells": int(dem.shape[0] * dem.shape[1]),
        "seconds": dt,
        "peaks": int(len(r.peaks)),
        "timings": r.attrs["timings_s"],
        "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
    }


def measure(vrt: Path, chunks: int | None, eps: float, out: Path | None = None) -> dict:
    cmd = [sys.executable, __file__, "--one", str(vrt), "--eps", str(eps)]
    if chunks:
        cmd += ["--chunks", str(chunks)]
    if out:
        cmd += ["--out", str(out)]
    res = subprocess.run(cmd, capture_output=True, text=True, check=True)
    return json.loads(res.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[6, 12, 24])
    ap.add_argument("--chunks", type=int, default=1024)
    ap.add_argument("--eps-ft", type=float, default=100.0)
    ap.add_argument("--dem", default="karakoram")
    ap.add_argument("--workdir", type=Path, default=Path("/tmp/orokit-scaling"))
    ap.add_argument("--in-memory-max", type=int, default=12, help="largest mosaic also run in memory")
    ap.add_argument("--one")
    ap.add_argument("--eps", type=float)
    ap.add_argument("--out")
    args = ap.parse_args()
    if args.one:
        print(json.dumps(run_one(args.one, args.chunks if "--chunks" in sys.argv else None, args.eps, args.out)))
        return

    import pandas as pd

    eps = args.eps_ft * FT
    print(f"chunked engine, chunks {args.chunks}^2, eps {args.eps_ft:g} ft, {os.cpu_count()} cores; "
          f"GeoTIFF tiles + VRT read lazily")
    print(f"{'mosaic':>8} {'M cells':>8} {'mode':>10} {'peaks':>8} {'seconds':>8} {'Mc/s':>6} {'peak RSS MB':>11}")
    rows = {}
    for n in args.sizes:
        vrt = write_mosaic(n, args.workdir, args.dem)
        modes = [("chunked", args.chunks)] + ([("in-memory", None)] if n <= args.in_memory_max else [])
        for mode, ch in modes:
            out = args.workdir / f"peaks_{n}_{mode}.parquet"
            m = measure(vrt, ch, eps, out)
            rows[n, mode] = m
            print(f"{n:>3}x{n:<4} {m['cells'] / 1e6:>8.1f} {mode:>10} {m['peaks']:>8d} {m['seconds']:>8.1f} "
                  f"{m['cells'] / m['seconds'] / 1e6:>6.1f} {m['rss_mb']:>11.0f}")
    summary = {"chunks": args.chunks, "eps_ft": args.eps_ft, "dem": args.dem,
               "runs": [{"mosaic": n, "mode": mode, **m} for (n, mode), m in rows.items()]}
    both = [n for n in args.sizes if (n, "in-memory") in rows]
    if both:
        n = max(both)
        c, i = rows[n, "chunked"], rows[n, "in-memory"]
        a = pd.read_parquet(args.workdir / f"peaks_{n}_chunked.parquet")
        b = pd.read_parquet(args.workdir / f"peaks_{n}_in-memory.parquet")
        print(f"largest raster both handle ({n}x{n}, {c['cells'] / 1e6:.1f} M cells): chunked/in-memory time "
              f"{c['seconds'] / i['seconds']:.2f}x, memory {c['rss_mb'] / i['rss_mb']:.2f}x; "
              f"peak tables identical: {a.equals(b)}")
        summary.update({"time_ratio_chunked_vs_in_memory": c["seconds"] / i["seconds"],
                        "memory_ratio_chunked_vs_in_memory": c["rss_mb"] / i["rss_mb"],
                        "tables_identical": bool(a.equals(b))})
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
