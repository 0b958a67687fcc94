"""Benchmark of Divide Tree synthesis: fidelity and time per stage on real regions.

For every region: analyse the reference DEM (``orokit.analyze``, eps = 30 m), build
its terrain type, synthesize a 90 x 90 km Divide Tree and print, per feature, the
maximum histogram-bin error (type bins and bins merged in pairs) and the earth
mover's distance between the synthesized and target distributions, plus the time
of every stage. Then time trees of exactly 2000 and 3000 peaks.

Usage::

    python benchmarks/synthesis.py [--data DIR] [--regions a,b,c] [--out reports/synthesis] [--seed 0]

Writes ``OUT/types/<region>.json``, ``OUT/fidelity.csv`` and ``OUT/timings.csv``
when ``--out`` is given. Not a test: run it by hand (a few seconds per region).
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import pandas as pd

DEFAULT_REGIONS = "alaska,appalachians,himalaya-everest,karakoram,norway,sahara"
PAPER = {"prominence": 0.03, "dominance": 0.03, "isolation_distance": 0.08}


def main(argv: list[str] | None = None) -> int:
    from orokit.analysis import analyze
    from orokit.io.dem import read_dem
    from orokit.synthesis.fidelity import compare_to_type
    from orokit.synthesis.terrain_type import TerrainType
    from orokit.synthesis.tree import synthesize_divide_tree

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(Path(__file__).resolve().parents[2] / "shared" / "data" / "dems"))
    ap.add_argument("--regions", default=DEFAULT_REGIONS)
    ap.add_argument("--size-km", type=float, default=90.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default=None)
    ap.add_argument("--no-scaling", action="store_true", help="skip the 2000/3000-peak timing runs")
    args = ap.parse_args(argv)
    data = Path(args.data)
    out = Path(args.out) if args.out else None
    size = args.size_km * 1000.0
    fid_rows, time_rows = [], []
    types = {}
    pd.set_option("display.width", 200)
    for region in args.regions.split(","):
        png = data / f"{region}.png"
        t0 = time.perf_counter()
        dem = read_dem(png, z_units="ft", cell_size_m=92.6)
        res = analyze(dem, min_prominence_m=30.0)
        tt = TerrainType.from_analysis(res, name=region)
        t_type = time.perf_counter() - t0
        types[region] = tt
        if out is not None:
            tt.save(out / "types" / f"{region}.json")
        t1 = time.perf_counter()
        tree = synthesize_divide_tree(tt, size_m=size, rng=args.seed)
        wall = time.perf_counter() - t1
        tree.validate()
        below = int((tree.prominence_table().query("key_saddle >= 0")["prominence"] < tt.min_prominence_m).sum())
        fid = compare_to_type(tree, tt)
        print(f"\n== {region}: {tree.n_peaks} peaks (type from {tt.provenance['n_peaks']} real peaks, "
              f"rho={tt.rho:g}), {wall:.2f} s wall, OT rounds {tree.attrs['ot_iterations']}, "
              f"peaks below eps: {below}, type built in {t_type:.2f} s")
        print(fid.round(4).to_string())
        print("stages (s):", tree.attrs["timings_s"])
        for feat, row in fid.iterrows():
            fid_rows.append({"region": region, "feature": feat, **row.to_dict()})
        time_rows.append({"region": region, "n_peaks": tree.n_peaks, "wall_s": wall, "ot_rounds": tree.attrs["ot_iterations"],
                          "below_eps": below, **{f"stage_{k}": v for k, v in tree.attrs["timings_s"].items()}})
    if not args.no_scaling:
        region = "appalachians" if "appalachians" in types else next(iter(types))
        for n in (2000, 3000):
            t1 = time.perf_counter()
            tree = synthesize_divide_tree(types[region], size_m=size, n_peaks=n, rng=args.seed)
            wall = time.perf_counter() - t1
            fid = compare_to_type(tree, types[region])
            print(f"\n== {region} with n_peaks={n}: {wall:.2f} s; max bin errors "
                  + ", ".join(f"{k} {v:.4f}" for k, v in fid["max_bin_error"].items()))
            print("stages (s):", tree.attrs["timings_s"])
            time_rows.append({"region": f"{region} (n={n})", "n_peaks": n, "wall_s": wall,
                              "ot_rounds": tree.attrs["ot_iterations"], "below_eps": tree.attrs["peaks_below_eps"],
                              **{f"stage_{k}": v for k, v in tree.attrs["timings_s"].items()}})
    fid_df = pd.DataFrame(fid_rows)
    summary = fid_df.pivot_table(index="feature", values=["max_bin_error", "max_bin_error_coarse"], aggfunc="max")
    print("\n== worst region per feature (max histogram-bin error)")
    print(summary.round(4).to_string())
    for feat, bound in PAPER.items():
        worst = float(summary.loc[feat, "max_bin_error"])
        print(f"{feat}: worst {worst:.4f} vs paper {bound:.2f} -> {'OK' if worst <= bound else 'WORSE'}")
    if out is not None:
        from orokit.io.atomic import atomic_path

        out.mkdir(parents=True, exist_ok=True)
        with atomic_path(out / "fidelity.csv") as tmp:
            fid_df.to_csv(tmp, index=False, float_format="%.6g")
        with atomic_path(out / "timings.csv") as tmp:
            pd.DataFrame(time_rows).to_csv(tmp, index=False, float_format="%.4f")
        print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
