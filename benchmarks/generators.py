"""Benchmark and figures of the generator backends.

Usage:
    python benchmarks/generators.py bench [--generator belhadj] [--type norway] [--size-km 60] [--res 30]
    python benchmarks/generators.py figures [--type norway] [--size-km 30] [--res 30]

``bench``: a Divide Tree of SIZE x SIZE km is synthesized from the committed terrain type
``reports/synthesis/types/TYPE.json`` (seed 0) and rendered at RES metres by the generator in a
fresh process (numba caches warmed on a coarse render first, so the peak RSS and the times
are the render's); prints time per stage and peak RSS, records them with the machine load in
``reports/benchmarks/generators.json`` (one entry per generator).

``figures``: Belhadj 2007 Figs. 3, 5 and 6 on a synthesized tree's skeleton (ridges + rivers):
MD alone, the cells MDI fills, MDI + MD, and the paper's own particle skeleton
(``skeleton=particles``, Figs. 1b/2); written to ``reports/generators/belhadj/``.
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

ROOT = Path(__file__).resolve().parents[1]
TYPES = ROOT / "reports" / "synthesis" / "types"


def _tree(type_name: str, size_km: float, seed: int):
    from orokit.synthesis.terrain_type import load_terrain_type
    from orokit.synthesis.tree import synthesize_divide_tree

    return synthesize_divide_tree(load_terrain_type(TYPES / f"{type_name}.json"), size_m=size_km * 1000.0, rng=seed)


def bench(generator: str, type_name: str, size_km: float, res: float, seed: int) -> dict:
    from orokit.generators import render_terrain
    from orokit.generators.base import tree_rivers
    from orokit.raster.rasterize import make_grid
    from orokit.raster.skeleton import tree_extent

    from orokit.generators import get_generator

    t0 = time.perf_counter()
    tree = _tree(type_name, size_km, seed)
    t_tree = time.perf_counter() - t0
    exemplar = None
    if "exemplar" in get_generator(generator).inputs:  # the region's real DEM (learning not timed below)
        from orokit.data import open_dataset_dem

        exemplar = open_dataset_dem(type_name)
    render_terrain(tree, generator=generator, cell_size_m=res * 10, seed=seed, exemplar=exemplar)  # warm caches
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024**2
    grid = make_grid(tree_extent(tree), res)
    t0 = time.perf_counter()
    rivers = tree_rivers(tree, grid)
    t_rivers = time.perf_counter() - t0
    t0 = time.perf_counter()
    dem = render_terrain(tree, generator=generator, grid=grid, rivers=rivers, seed=seed, exemplar=exemplar)
    t_render = time.perf_counter() - t0
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024**2
    stages = json.loads(dem.attrs["timings"])
    stages["rivers"] = round(t_rivers, 3)
    return {"generator": generator, "type": type_name, "size_km": size_km, "res_m": res, "seed": seed,
            "peaks": int(tree.n_peaks), "shape": f"{dem.shape[1]}x{dem.shape[0]}", "tree_s": round(t_tree, 2),
            "render_s": round(t_render + t_rivers, 3), "stages_s": stages, "peak_rss_gb": round(rss, 3),
            "rss_before_render_gb": round(rss0, 3), "load_average_after": list(os.getloadavg())}


def figures(type_name: str, size_km: float, res: float, seed: int, out: Path) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from orokit.generators import belhadj as B
    from orokit.generators.base import tree_rivers
    from orokit.raster.rasterize import make_grid
    from orokit.raster.skeleton import tree_extent
    from orokit.reports.generators import plot_belhadj_stage

    tree = _tree(type_name, size_km, seed)
    grid = make_grid(tree_extent(tree), res)
    z, st = B.tree_skeleton(tree, tree_rivers(tree, grid), grid)
    p = B.BelhadjParams()
    md_only, st_md = B.interpolate(z, st, params=B.BelhadjParams(mdi=False), rng=np.random.default_rng(seed))
    # MDI alone (Fig. 5): the MD stage is skipped by reading the state before it
    n = B.padded_size(*z.shape)
    zz = np.zeros((n, n))
    s5 = np.zeros((n, n), np.uint8)
    zz[: z.shape[0], : z.shape[1]] = np.where(st == 1, z, 0.0)
    s5[: z.shape[0], : z.shape[1]] = st
    from orokit.generators import _belhadj_kernels as K

    K.mdi(zz, s5, np.random.default_rng(seed).uniform(-1, 1, (n, n)).astype(np.float32),
          p.displacement_m_per_cell, p.hurst, B.MODE[p.subdivision])
    s5 = s5[: z.shape[0], : z.shape[1]]
    full, st_full = B.interpolate(z, st, params=p, rng=np.random.default_rng(seed))
    out.mkdir(parents=True, exist_ok=True)
    written = []
    panels = [("fig2_skeleton.png", z, st, "skeleton", "skeleton: ridges (peak to saddle) + rivers"),
              ("fig3_md.png", md_only, st_md, "terrain", "Fig. 3: MD alone on the skeleton"),
              ("fig5_mdi.png", z, s5, "mdi", f"Fig. 5: MDI ({int((s5 == 2).sum())} cells, black)"),
              ("fig6_mdi_md.png", full, st_full, "terrain", "Fig. 6: MDI then MD")]
    for name, a, s, kind, title in panels:
        fig, ax = plt.subplots(figsize=(6, 6))
        plot_belhadj_stage(ax, a, s, cell_size_m=res, kind=kind, title=title)
        fig.tight_layout()
        fig.savefig(out / name, dpi=110)
        plt.close(fig)
        written.append(out / name)
    # a zoom on MD vs MDI+MD where the skeleton is dense (the paper's discontinuities)
    k = min(200, z.shape[0])
    fig, axes = plt.subplots(1, 2, figsize=(10, 5))
    plot_belhadj_stage(axes[0], md_only[:k, :k], st[:k, :k], cell_size_m=res, kind="terrain", title="MD alone (zoom)")
    plot_belhadj_stage(axes[1], full[:k, :k], st[:k, :k], cell_size_m=res, kind="terrain", title="MDI + MD (zoom)")
    fig.tight_layout()
    fig.savefig(out / "md_vs_mdi_md_zoom.png", dpi=110)
    plt.close(fig)
    written.append(out / "md_vs_mdi_md_zoom.png")
    # the paper's own skeleton (skeleton=particles, §2): Fig. 1b (blended ridges + kept rivers), Fig. 2, result
    levels = np.concatenate([tree.peaks["elevation"].to_numpy(), tree.saddles["elevation"].to_numpy()])
    pp = B.BelhadjParams(skeleton="particles")
    sk = B.particle_skeleton(grid, top=float(levels.max()), base=float(levels.min()), params=pp,
                             rng=np.random.default_rng(seed))
    pfull, pst = B.interpolate(sk.z, sk.state, params=pp, rng=np.random.default_rng(seed))
    fig, axes = plt.subplots(1, 3, figsize=(15, 5.4))
    axes[0].imshow(sk.blended, cmap="terrain", interpolation="nearest")
    rr, cc = np.nonzero(sk.river)
    axes[0].plot(cc, rr, ",", color="blue")
    axes[0].set_title(f"Fig. 1b: {pp.ridge_pairs} ridge pairs blended, {int(sk.river_kept.sum())} of "
                      f"{pp.river_particles} river particles kept", fontsize=9)
    axes[0].set_xticks([])
    axes[0].set_yticks([])
    plot_belhadj_stage(axes[1], sk.z, sk.state, cell_size_m=res, kind="skeleton", title="Fig. 2: particle skeleton")
    plot_belhadj_stage(axes[2], pfull, pst, cell_size_m=res, kind="terrain", title="MDI then MD on it")
    fig.tight_layout()
    fig.savefig(out / "particles.png", dpi=90)
    plt.close(fig)
    written.append(out / "particles.png")
    return written


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("what", choices=["bench", "figures"])
    ap.add_argument("--generator", default="belhadj")
    ap.add_argument("--type", dest="type_name", default="norway")
    ap.add_argument("--size-km", type=float, default=None)
    ap.add_argument("--res", type=float, default=30.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.what == "figures":
        for p in figures(a.type_name, a.size_km or 30.0, a.res, a.seed, ROOT / "reports" / "generators" / "belhadj"):
            print(p)
        return
    size = a.size_km or 60.0
    if a.child:
        print(json.dumps(bench(a.generator, a.type_name, size, a.res, a.seed)))
        return
    cmd = [sys.executable, __file__, "bench", "--child", "--generator", a.generator, "--type", a.type_name,
           "--size-km", str(size), "--res", str(a.res), "--seed", str(a.seed)]
    res = json.loads(subprocess.run(cmd, check=True, capture_output=True, text=True).stdout.strip().splitlines()[-1])
    print(f"{a.generator}: {res['shape']} from {res['peaks']} peaks: render {res['render_s']} s, "
          f"peak RSS {res['peak_rss_gb']} GB (tree synthesis {res['tree_s']} s; load {res['load_average_after']})")
    for k, v in res["stages_s"].items():
        print(f"  {k:10s} {v:7.3f} s")
    sys.path.insert(0, str(Path(__file__).parent))
    from _record import OUT, record

    prev = {}
    if (OUT / "generators.json").exists():
        prev = json.loads((OUT / "generators.json").read_text()).get("results", {})
    prev[a.generator] = res
    print(f"recorded in {record('generators', prev)}")


if __name__ == "__main__":
    main()
