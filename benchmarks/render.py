"""Benchmark of ``render_elevation``: time per stage and peak memory.

Usage: python benchmarks/render.py [--dem appalachians] [--size-km 90] [--res 30] [--erosion/--no-erosion]

A terrain type is derived from a shared DEM, a Divide Tree of SIZE x SIZE km is synthesized
from it, and the tree is rendered at RES metres (each variant in its own process so the
peak RSS is that variant's). Prints one line per stage and the round-trip numbers, and
records them (with the machine load) in reports/benchmarks/render.json.
"""
from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
from pathlib import Path


def run(dem_name: str, size_km: float, res: float, erosion: bool, seed: int) -> dict:
    import orokit
    from orokit.data import open_dataset_dem
    from orokit.raster.render import render_elevation
    from orokit.raster.skeleton import tree_extent
    from orokit.synthesis.terrain_type import TerrainType
    from orokit.synthesis.tree import synthesize_divide_tree
    from orokit.validate.roundtrip import roundtrip

    dem = open_dataset_dem(dem_name)  # the manifest knows the units and the cell size
    ttype = TerrainType.from_analysis(orokit.analyze(dem, min_prominence_m=30.0), name=dem_name)
    t0 = time.perf_counter()
    tree = synthesize_divide_tree(ttype, size_m=size_km * 1000.0, rng=seed)
    t_tree = time.perf_counter() - t0
    render_elevation(tree, cell_size_m=res * 10, erosion=erosion, rng=seed)  # warm numba caches
    t0 = time.perf_counter()
    out = render_elevation(tree, cell_size_m=res, extent=tree_extent(tree), erosion=erosion, rng=seed)
    t_render = time.perf_counter() - t0
    rss_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024**2
    t0 = time.perf_counter()
    s = roundtrip(out, tree, min_prominence_m=30.0).summary()
    t_rt = time.perf_counter() - t0
    return {"dem": dem_name, "size_km": size_km, "res_m": res, "erosion": erosion, "peaks": tree.n_peaks,
            "shape": f"{out.shape[1]}x{out.shape[0]}", "tree_s": round(t_tree, 2), "render_s": round(t_render, 2),
            "stages_s": json.loads(out.attrs["timings"]), "peak_rss_gb": round(rss_gb, 2),
            "roundtrip_s": round(t_rt, 2), "recovered_share": round(s["recovered_share"], 4),
            "extra_share": round(s["extra_share"], 4)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--dem", default="appalachians")
    ap.add_argument("--size-km", type=float, default=90.0)
    ap.add_argument("--res", type=float, default=30.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--variant", choices=["both", "plain", "eroded"], default="both")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--erosion", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child:
        print(json.dumps(run(a.dem, a.size_km, a.res, a.erosion, a.seed)))
        return
    variants = {"both": [False, True], "plain": [False], "eroded": [True]}[a.variant]
    runs = []
    for ero in variants:
        cmd = [sys.executable, __file__, "--child", "--dem", a.dem, "--size-km", str(a.size_km), "--res", str(a.res),
               "--seed", str(a.seed)] + (["--erosion"] if ero else [])
        res = json.loads(subprocess.run(cmd, check=True, capture_output=True, text=True).stdout.strip().splitlines()[-1])
        runs.append(res)
        print(f"{'with' if ero else 'without'} erosion: {res['shape']} from {res['peaks']} peaks: "
              f"render {res['render_s']} s, peak RSS {res['peak_rss_gb']} GB (tree synthesis {res['tree_s']} s)")
        for k, v in res["stages_s"].items():
            print(f"  {k:10s} {v:7.2f} s")
        print(f"  round trip: {100 * res['recovered_share']:.1f} % recovered, {100 * res['extra_share']:.1f} % extra "
              f"(re-analysis {res['roundtrip_s']} s)")
    sys.path.insert(0, str(Path(__file__).parent))
    from _record import record

    print(f"recorded in {record('render', {'dem': a.dem, 'size_km': a.size_km, 'res_m': a.res, 'seed': a.seed, 'runs': runs})}")


if __name__ == "__main__":
    main()
