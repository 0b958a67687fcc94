"""orokit vs Kirmse's C++ ``prominence``: whole processes, same input, same run (issue 13).

1. Builds Kirmse's program from ``../shared/baselines/mountains`` in a temporary folder
   (or reuses ``--kirmse-bin``).
2. Writes the same n x n mosaic of a 648 x 648 real DEM (mirrored, continuous seams;
   integer feet) for both programs: one CUSTOM FLT tile holding z / 32 for Kirmse (its
   tile loader turns every sample more than 1000 units above a 4-neighbour into nodata;
   z / 32 is exact in float32 and stays below that), and a float32 GeoTIFF in metres
   (z x 0.3048) for orokit.
3. After one untimed run of each (numba's cache, page cache), times, as whole processes
   with ``/usr/bin/time -v`` and alternating, ``--reps`` times:
   Kirmse ``prominence -t 1`` + ``merge_divide_trees -f -t 1`` (sum of both, RSS = max),
   ``orokit -q analyze DEM -o OUT --no-progress --no-isolation`` and the same with isolation
   (with ``--one-core``, also the first on one core: orokit's own 2-core ratio from the same,
   alternating runs). Each run also records the seconds its threads waited for a core
   (run-queue delay): other processes on the machine show there, not in the CPU time.
4. Checks that the peak sets are identical (cells, elevations and prominences).

Prints the median times, both ratios (Kirmse / orokit; > 1 = orokit faster), both peak
RSS, and records ``reports/benchmarks/vs_kirmse.json`` with the machine load.

Run:  .venv/bin/python benchmarks/vs_kirmse.py [--tiles 6 12] [--reps 3] [--dem himalaya-everest] [--one-core]
"""
from __future__ import annotations

import argparse
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

FT = 0.3048
#: Kirmse's input is z / SCALE (see the module docstring)
SCALE = 32.0
#: threshold in feet; half a foot off the integer-feet prominences, so ">" and ">=" agree
EPS_FT = 99.5
REPO = Path(__file__).resolve().parents[1]
BASELINE = REPO.parent / "shared" / "baselines" / "mountains"


def mosaic(z: np.ndarray, n: int) -> np.ndarray:
    """n x n mosaic of z, mirrored so neighbouring tiles share their edges' values."""
    rows = []
    for i in range(n):
        zi = z if i % 2 == 0 else z[::-1]
        rows.append(np.concatenate([zi if j % 2 == 0 else zi[:, ::-1] for j in range(n)], axis=1))
    return np.ascontiguousarray(np.concatenate(rows, axis=0))


def build_kirmse(workdir: Path, source: Path = BASELINE) -> Path:
    """Copy Kirmse's source into ``workdir`` and build it; returns the folder of the binaries."""
    if not (source / "code" / "Makefile").exists():
        raise FileNotFoundError(f"Kirmse's source is not at {source} (expected ../shared/baselines/mountains)")
    dst = workdir / "mountains"
    if dst.exists():
        shutil.rmtree(dst)
    shutil.copytree(source, dst)
    subprocess.run(["make", "-C", str(dst / "code"), "-j2"], check=True, capture_output=True, text=True)
    return dst / "code" / "release"


def write_kirmse_tile(z_ft: np.ndarray, folder: Path) -> int:
    """Write ``z_ft`` (integer feet, NaN = nodata) / SCALE, turned by 180 degrees, as the CUSTOM tile at (0, 0).

    Kirmse breaks ties between equal heights the other way round (later in raster order
    = higher); the half turn reverses the raster order, so both programs break ties
    alike and pick the same cells (:func:`parse_kirmse_results` turns them back). A
    non-square raster is padded with nodata to S x S. Returns S (samples per side).
    """
    z_ft = z_ft[::-1, ::-1]
    h, w = z_ft.shape
    s = max(h, w)
    tile = np.full((s, s), -999999.0, np.float32)
    v = (z_ft / SCALE).astype(np.float32)
    tile[:h, :w] = np.where(np.isnan(v), np.float32(-999999.0), v)
    folder.mkdir(parents=True, exist_ok=True)
    tile.astype("<f4").tofile(folder / "tile_01x00_000x00.flt")
    (folder / "tile_01x00_000x00.hdr").write_text(
        f"NCOLS {s}\nNROWS {s}\nNBANDS 1\nNBITS 32\nPIXELTYPE FLOAT\nBYTEORDER I\n"
        f"ULXMAP 0\nULYMAP 1\nXDIM {1.0 / s!r}\nYDIM {1.0 / s!r}\nNODATA -999999\n"
    )
    return s


def write_geotiff_m(z_ft: np.ndarray, path: Path, cell_size_m: float = 92.61) -> Path:
    """float32 GeoTIFF in metres (UTM 45N, square cells) of a raster in feet."""
    import rasterio
    from affine import Affine

    z = (z_ft * FT).astype(np.float32)
    with rasterio.open(
        path, "w", driver="GTiff", width=z.shape[1], height=z.shape[0], count=1, dtype="float32",
        crs="EPSG:32645", transform=Affine(cell_size_m, 0.0, 300000.0, 0.0, -cell_size_m, 4000000.0), nodata=np.nan,
        tiled=True, blockxsize=512, blockysize=512,
    ) as ds:
        ds.write(z, 1)
        ds.set_band_unit(1, "m")
    return path


def kirmse_commands(bin_dir: Path, tiles: Path, out: Path, s: int, eps_ft: float = EPS_FT) -> list[list[str]]:
    """The two commands of a single-thread Kirmse run on the tile at (0, 0)."""
    m = repr(eps_ft / SCALE)
    return [
        [str(bin_dir / "prominence"), "-f", f"CUSTOM-1-{s}", "-i", str(tiles), "-o", str(out), "-m", m, "-t", "1",
         "--", "0", "1", "0", "0"],
        # the pruned tree's file name is completed by a glob at run time
        [str(bin_dir / "merge_divide_trees"), "-f", "-m", m, "-t", "1", str(out / "results"),
         str(out / "prominence-00x00-000x00-divide_tree_pruned_*.dvt")],
    ]


def parse_kirmse_results(path: Path, s: int, shape: tuple[int, int] | None = None, *,
                         scale: float = SCALE) -> pd.DataFrame:
    """Kirmse's ``results.txt`` (``lat,lng,elevation,saddle_lat,saddle_lng,prominence``) as a table.

    Sample (col, row) of the tile at (0, 0) with ``s`` samples per side is at
    lat = 1 - row / s, lng = col / s. With ``shape`` (the raster's (h, w)), cells are
    turned back by 180 degrees (see :func:`write_kirmse_tile`). Elevations and prominences are multiplied by
    ``scale`` and rounded to integers (the input held integer feet / scale; the file
    has two decimals). Returns row, col, elevation, saddle_row, saddle_col, prominence
    (feet) sorted by (row, col); a peak without key saddle has saddle_row = -1.
    """
    a = np.loadtxt(path, delimiter=",", ndmin=2) if Path(path).stat().st_size else np.zeros((0, 6))
    row = np.rint((1.0 - a[:, 0]) * s).astype(np.int64)
    col = np.rint(a[:, 1] * s).astype(np.int64)
    srow = np.rint((1.0 - a[:, 3]) * s).astype(np.int64)
    scol = np.rint(a[:, 4] * s).astype(np.int64)
    no_saddle = (a[:, 3] == 0) & (a[:, 4] == 0)
    if shape is not None:
        h, w = shape
        row, col, srow, scol = h - 1 - row, w - 1 - col, h - 1 - srow, w - 1 - scol
    srow[no_saddle] = -1
    scol[no_saddle] = -1
    df = pd.DataFrame({
        "row": row, "col": col, "elevation": np.rint(a[:, 2] * scale),
        "saddle_row": srow, "saddle_col": scol, "prominence": np.rint(a[:, 5] * scale),
    })
    return df.sort_values(["row", "col"], kind="stable").reset_index(drop=True)


def _plateau_first_cell(z: np.ndarray, r: int, c: int) -> tuple[int, int]:
    """First cell in raster order of the 8-connected equal-elevation region holding (r, c)."""
    h, w = z.shape
    v = z[r, c]
    seen = {(r, c)}
    todo = [(r, c)]
    while todo:
        i, j = todo.pop()
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                a, b = i + di, j + dj
                if 0 <= a < h and 0 <= b < w and (a, b) not in seen and z[a, b] == v:
                    seen.add((a, b))
                    todo.append((a, b))
    return min(seen)


def compare_peaks(kirmse: pd.DataFrame, ours: pd.DataFrame, z_ft: np.ndarray) -> dict:
    """Compare Kirmse's peaks with orokit's (row, col, elevation ft, prominence ft).

    A Kirmse peak on a flat summit is moved to the summit's first cell in raster order
    (orokit's convention) before comparing. Returns counts and ``identical``.
    """
    k = kirmse.copy()
    ours_cells = set(zip(ours["row"].tolist(), ours["col"].tolist()))
    moved = 0
    for i, (r, c) in enumerate(zip(k["row"].tolist(), k["col"].tolist())):
        if (r, c) not in ours_cells:
            r2, c2 = _plateau_first_cell(z_ft, r, c)
            if (r2, c2) != (r, c):
                k.loc[i, ["row", "col"]] = [r2, c2]
                moved += 1
    kc = set(zip(k["row"].tolist(), k["col"].tolist()))
    only_k, only_o = kc - ours_cells, ours_cells - kc
    a = k.set_index(["row", "col"]).sort_index()
    b = ours.set_index(["row", "col"]).sort_index()
    common = a.index.intersection(b.index)
    prom_diff = int((a.loc[common, "prominence"].to_numpy() != b.loc[common, "prominence"].to_numpy()).sum())
    elev_diff = int((a.loc[common, "elevation"].to_numpy() != b.loc[common, "elevation"].to_numpy()).sum())
    # (elevation, prominence) pairs do not depend on how ties are broken
    pairs_k = sorted(zip(k["elevation"].tolist(), k["prominence"].tolist()))
    pairs_o = sorted(zip(ours["elevation"].tolist(), ours["prominence"].tolist()))
    return {
        "same_elevation_prominence_pairs": pairs_k == pairs_o,
        "kirmse_peaks": int(len(k)), "orokit_peaks": int(len(ours)), "moved_to_plateau_start": moved,
        "only_kirmse": len(only_k), "only_orokit": len(only_o), "prominence_differs": prom_diff,
        "elevation_differs": elev_diff,
        "identical": not only_k and not only_o and prom_diff == 0 and elev_diff == 0,
    }


def orokit_peaks_ft(outdir: Path) -> pd.DataFrame:
    """orokit's peaks.parquet as row, col, elevation, prominence in (rounded) feet."""
    p = pd.read_parquet(outdir / "peaks.parquet", columns=["row", "col", "elevation", "prominence"])
    return pd.DataFrame({"row": p["row"].to_numpy(np.int64), "col": p["col"].to_numpy(np.int64),
                         "elevation": np.rint(p["elevation"] / FT), "prominence": np.rint(p["prominence"] / FT)})


_TIME_RE = {
    "wall": re.compile(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): (\S+)"),
    "rss": re.compile(r"Maximum resident set size \(kbytes\): (\d+)"),
    "user": re.compile(r"User time \(seconds\): (\S+)"),
    "sys": re.compile(r"System time \(seconds\): (\S+)"),
}


def parse_time_v(stderr: str) -> dict:
    """Wall seconds, CPU seconds and peak RSS (MB) from ``/usr/bin/time -v`` output."""
    wall = _TIME_RE["wall"].findall(stderr)[-1]
    secs = 0.0
    for part in wall.split(":"):
        secs = secs * 60 + float(part)
    return {"seconds": secs, "cpu_s": float(_TIME_RE["user"].findall(stderr)[-1])
            + float(_TIME_RE["sys"].findall(stderr)[-1]),
            "rss_mb": int(_TIME_RE["rss"].findall(stderr)[-1]) / 1024.0}


def _thread_schedstats(pid: int) -> dict[str, tuple[int, int]]:
    """(ns run, ns waited for a core while runnable) of every thread of process ``pid`` (Linux; else {})."""
    out = {}
    try:
        tids = os.listdir(f"/proc/{pid}/task")
    except OSError:
        return out
    for tid in tids:
        try:
            with open(f"/proc/{pid}/task/{tid}/schedstat") as f:
                run, wait = f.read().split()[:2]
            out[tid] = (int(run), int(wait))
        except (OSError, ValueError):
            pass
    return out


def _child_pid(pid: int) -> int | None:
    try:
        with open(f"/proc/{pid}/task/{pid}/children") as f:
            kids = f.read().split()
    except OSError:
        return None
    return int(kids[0]) if kids else None


def _steal_ticks() -> int:
    """Clock ticks the hypervisor gave the machine's CPUs to others (``/proc/stat`` steal; 0 elsewhere)."""
    try:
        with open("/proc/stat") as f:
            fields = f.readline().split()
        return int(fields[8]) if fields[0] == "cpu" and len(fields) > 8 else 0
    except (OSError, ValueError):
        return 0


#: seconds between two samples of the timed process's threads (~1 % of a core)
SAMPLE_S = 0.05


def timed(cmd: list[str], env: dict | None = None) -> dict:
    """Run ``cmd`` under ``/usr/bin/time -v``; returns :func:`parse_time_v` of it and ``wait_s``.

    ``wait_s``: the seconds the process's threads were ready to run but waited for a core
    (run-queue delay, ``/proc/PID/task/*/schedstat``, sampled every ``SAMPLE_S``; a thread's last
    interval before it ends is missed). On a quiet machine it is near 0; other processes
    taking a core show up in it, and lengthen a 2-core run more than a 1-core one.
    ``steal_s``: CPU seconds the hypervisor took from this machine's cores meanwhile (all cores;
    invisible to the wait above: a virtual machine's neighbours).
    """
    import time

    if "*" in cmd[-1]:
        import glob

        found = sorted(glob.glob(cmd[-1]))
        if len(found) != 1:
            raise RuntimeError(f"expected one file matching {cmd[-1]}, found {found}")
        cmd = cmd[:-1] + found
    steal0 = _steal_ticks()
    proc = subprocess.Popen(["/usr/bin/time", "-v", *cmd], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env)
    seen: dict[str, tuple[int, int]] = {}
    child = None
    while proc.poll() is None:
        child = child or _child_pid(proc.pid)
        if child is not None:
            seen.update(_thread_schedstats(child))
        time.sleep(SAMPLE_S)
    _, stderr = proc.communicate()
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({proc.returncode}):\n{stderr[-2000:]}")
    return {**parse_time_v(stderr), "wait_s": sum(w for _, w in seen.values()) / 1e9,
            "steal_s": (_steal_ticks() - steal0) / os.sysconf("SC_CLK_TCK")}


def run_kirmse(bin_dir: Path, tiles: Path, out: Path, s: int, *, eps_ft: float = EPS_FT) -> dict:
    """Kirmse's two processes into a fresh ``out``: summed wall, CPU and wait seconds, max RSS."""
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    parts = [timed(cmd) for cmd in kirmse_commands(bin_dir, tiles, out, s, eps_ft)]
    return {"seconds": sum(p["seconds"] for p in parts), "cpu_s": sum(p["cpu_s"] for p in parts),
            "wait_s": sum(p["wait_s"] for p in parts), "steal_s": sum(p["steal_s"] for p in parts),
            "rss_mb": max(p["rss_mb"] for p in parts),
            "parts_s": [p["seconds"] for p in parts]}


def orokit_command(tif: Path, out: Path, *, isolation: bool, eps_ft: float = EPS_FT) -> list[str]:
    exe = Path(sys.executable).with_name("orokit")
    cmd = [str(exe), "-q", "analyze", str(tif), "-o", str(out), "--no-progress", "--overwrite",
           "--min-prominence", repr(eps_ft * FT)]
    return cmd + ([] if isolation else ["--no-isolation"])


def run_orokit(tif: Path, out: Path, *, isolation: bool, env: dict | None = None, cores: int | None = None) -> dict:
    """orokit's process; with ``cores``, pinned to that many cores (``taskset``: every thread of it)."""
    cmd = orokit_command(tif, out, isolation=isolation)
    if cores:
        cmd = ["taskset", "-c", f"0-{cores - 1}", *cmd]
    return timed(cmd, env=env)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--tiles", type=int, nargs="+", default=[6, 12])
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--dem", default="himalaya-everest")
    ap.add_argument("--kirmse-bin", type=Path, default=None, help="folder of already built Kirmse binaries")
    ap.add_argument("--workdir", type=Path, default=None, help="default: a temporary folder, removed at the end")
    ap.add_argument("--threads", type=int, default=None,  # also pins orokit to that many cores (taskset)
                    help="NUMBA_NUM_THREADS for orokit, and orokit pinned to that many cores (taskset; default: all "
                         "cores, unpinned)")
    ap.add_argument("--one-core", action="store_true",
                    help="also run orokit (no isolation) on one core (NUMBA_NUM_THREADS=1, taskset -c 0) in every "
                         "repetition, alternating with the others: prints its own 2-core ratio (issue 13: >= 1.6x)")
    ap.add_argument("--no-record", action="store_true", help="do not write reports/benchmarks/vs_kirmse.json")
    args = ap.parse_args()

    from orokit.data import open_dataset_dem

    tmp = None
    if args.workdir is None:
        tmp = tempfile.TemporaryDirectory(prefix="orokit-vs-kirmse-")
        work = Path(tmp.name)
    else:
        work = args.workdir
        work.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ)
    if args.threads:
        env["NUMBA_NUM_THREADS"] = str(args.threads)
    try:
        bin_dir = args.kirmse_bin or build_kirmse(work)
        base = open_dataset_dem(args.dem)
        z0_ft = np.rint(np.asarray(base.values, np.float64) / FT)  # the PNG's integer feet
        load0 = os.getloadavg()
        print(f"{args.dem}, eps {EPS_FT} ft, {args.reps} alternating reps, {os.cpu_count()} cores, "
              f"load average {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}")
        print(f"{'mosaic':>7} {'M cells':>7} {'Kirmse s':>8} {'orokit s':>8} {'+iso s':>7} {'ratio':>6} "
              f"{'ratio+iso':>9} {'RSS MB K/o/o+iso':>18} {'peaks':>8} identical")
        rows = []
        for n in args.tiles:
            z_ft = mosaic(z0_ft, n)
            folder = work / f"mosaic_{n}x{n}"
            s = write_kirmse_tile(z_ft, folder / "tiles")
            tif = write_geotiff_m(z_ft, folder / "mosaic.tif")
            runs: dict[str, list[dict]] = {"kirmse": [], "orokit": [], "orokit_isolation": []}
            if args.one_core:
                runs["orokit_one_core"] = []
            # untimed: fills numba's cache after a code change (a first run compiles the kernels) and the
            # page cache of both inputs, so the timed repetitions all start alike
            run_kirmse(bin_dir, folder / "tiles", folder / "kirmse", s)
            run_orokit(tif, folder / "orokit_iso", isolation=True, env=env, cores=args.threads)
            loads = []
            for _ in range(args.reps):
                loads.append(os.getloadavg()[0])
                runs["kirmse"].append(run_kirmse(bin_dir, folder / "tiles", folder / "kirmse", s))
                runs["orokit"].append(run_orokit(tif, folder / "orokit", isolation=False, env=env, cores=args.threads))
                runs["orokit_isolation"].append(run_orokit(tif, folder / "orokit_iso", isolation=True, env=env,
                                                           cores=args.threads))
                if args.one_core:
                    runs["orokit_one_core"].append(run_orokit(tif, folder / "orokit_1", isolation=False,
                                                              env={**env, "NUMBA_NUM_THREADS": "1"}, cores=1))
            loads.append(os.getloadavg()[0])
            cmp = compare_peaks(parse_kirmse_results(folder / "kirmse" / "results.txt", s, z_ft.shape),
                                orokit_peaks_ft(folder / "orokit"), z_ft)
            med = {k: statistics.median(r["seconds"] for r in v) for k, v in runs.items()}
            rss = {k: max(r["rss_mb"] for r in v) for k, v in runs.items()}
            row = {
                "mosaic": n, "cells": int(z_ft.size), "median_s": med, "peak_rss_mb": rss,
                "ratio_no_isolation": med["kirmse"] / med["orokit"],
                "ratio_with_isolation": med["kirmse"] / med["orokit_isolation"],
                "runs": runs, "load_average_1min_during": loads, "peaks": cmp,
            }
            rows.append(row)
            print(f"{n:>3}x{n:<3} {z_ft.size / 1e6:>7.1f} {med['kirmse']:>8.2f} {med['orokit']:>8.2f} "
                  f"{med['orokit_isolation']:>7.2f} {row['ratio_no_isolation']:>5.2f}x "
                  f"{row['ratio_with_isolation']:>8.2f}x {rss['kirmse']:>6.0f}/{rss['orokit']:.0f}/"
                  f"{rss['orokit_isolation']:.0f} {cmp['orokit_peaks']:>8d} {cmp['identical']}"
                  f"  (load {min(loads):.1f}-{max(loads):.1f})")
            wait = {k: statistics.median(r["wait_s"] for r in v) for k, v in runs.items()}
            steal = {k: statistics.median(r["steal_s"] for r in v) for k, v in runs.items()}
            row["median_wait_s"], row["median_steal_s"] = wait, steal
            print("        run-queue wait s (median): " + ", ".join(f"{k} {v:.2f}" for k, v in wait.items()))
            print("        hypervisor steal s (median): " + ", ".join(f"{k} {v:.2f}" for k, v in steal.items()))
            if args.one_core:
                row["ratio_two_cores"] = med["orokit_one_core"] / med["orokit"]
                print(f"        orokit one core {med['orokit_one_core']:.2f} s / {med['orokit']:.2f} s: "
                      f"{row['ratio_two_cores']:.2f}x (issue 13: >= 1.6x at 60 M cells)")
            if not cmp["identical"]:
                print(f"   peak sets differ: {cmp}")
            if not args.no_record:  # after every mosaic: a long run interrupted keeps what it measured
                sys.path.insert(0, str(Path(__file__).parent))
                from _record import record

                path = record("vs_kirmse", {"dem": args.dem, "eps_ft": EPS_FT, "reps": args.reps,
                                            "orokit_numba_threads": env.get("NUMBA_NUM_THREADS", "all cores"),
                                            "orokit_cores": args.threads or "all (unpinned)",
                                            "mosaics": rows})
        print("ratio = Kirmse (prominence -t 1 + merge_divide_trees -f) / orokit, whole processes, "
              "median wall time; > 1: orokit faster")
        if not args.no_record and rows:
            print(f"recorded in {path}")
    finally:
        if tmp is not None:
            tmp.cleanup()


if __name__ == "__main__":
    main()
