"""The region classifier's main choices over several disk layouts (issue 12): mean and spread, not one draw.

Usage: python benchmarks/classification_layouts.py [--analysis-dir reports/analysis] [--seeds 0 1 2]
       [--runs 20] [--block-runs 1] [--out reports/classification/layouts.md]

The placement of the disks alone moves the spatial hold-out of one variant by ~3 points
(``ablation.md``), more than most choices change it. Here every row is evaluated on the
disk layouts of each ``--seed`` (blue-noise placement drawn with that seed, as in
``classification_ablation.py``): held-out strip (``--runs`` runs) and spatial k-fold blocks
(``--block-runs`` runs, blocks of R/2), training disks > 2 R from the held-out disks,
R = 10 km. The table gives the mean over the layouts and the per-layout figures; a row is
better than another only when it is better on every layout or by more than the spread.
Results go to ``--out`` (Markdown) and ``reports/benchmarks/classification_layouts.json``
(with timings and the machine load).
"""
from __future__ import annotations

import argparse
import contextlib
import json
import dataclasses
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def rows():
    from orokit.sampling.feature_sets import FeatureSet

    oro = FeatureSet.orometry()
    ter = FeatureSet.named("terrain")
    plain = dataclasses.replace(oro, name="v", saddles=False, pattern=False)
    return [
        ("session-4 default: orometry without the key-saddle features", plain, {}),
        ("orometry (default): + key saddles (relief, col ratio, saddle height)", oro, {}),
        ("orometry + spatial pattern", dataclasses.replace(oro, name="v", pattern=True), {}),
        ("orometry, Random Forest", oro, {"classifier": "rf"}),
        ("orometry, gradient boosting (HistGradientBoosting)", oro, {"classifier": "hgb"}),
        ("orometry, ExtraTrees with balanced class weights", oro, {"estimator_options": {"class_weight": "balanced"}}),
        ("terrain: orometry + the DEM's terrain in each disk (slope, relief, curvature, hypsometry, spectrum, "
         "drainage)", ter, {}),
        ("terrain features of the DEM only (no orometry)", dataclasses.replace(ter, name="v", histograms=(),
                                                                             summaries=False, elevation=False,
                                                                             saddles=False), {}),
        ("terrain, ExtraTrees with max_features 1/3", ter, {"estimator_options": {"max_features": 1 / 3}}),
    ]


@contextlib.contextmanager
def estimator_options(options: dict | None):
    """Every classifier made inside gets these scikit-learn parameters (experiment rows only)."""
    import orokit.classify.train as train

    if not options:
        yield
        return
    original = train.make_classifier

    def patched(*args, **kwargs):
        pipe = original(*args, **kwargs)
        pipe[-1].set_params(**options)
        return pipe

    train.make_classifier = patched
    try:
        yield
    finally:
        train.make_classifier = original


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--analysis-dir", type=Path, default=ROOT / "reports" / "analysis")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--block-runs", type=int, default=1)
    ap.add_argument("--rows", type=int, nargs="*", default=None, help="indices of the rows to run (default: all)")
    ap.add_argument("--out", type=Path, default=ROOT / "reports" / "classification" / "layouts.md")
    a = ap.parse_args()
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from _record import record
    from classification_ablation import features

    from orokit.classify.train import evaluate
    from orokit.io.atomic import write_text_atomic

    inputs = sorted(p for p in a.analysis_dir.iterdir() if (p / "analysis.json").exists())
    if len(inputs) < 2:
        raise SystemExit(f"{a.analysis_dir} holds no analysis folders; run `make analysis` first")
    table = rows()
    chosen = range(len(table)) if a.rows is None else a.rows
    results = []
    for i in chosen:
        title, fs, ekw = table[i]
        res = {"variant": title, "feature_set": fs.to_dict(), "n_features": len(fs.columns), **ekw, "layouts": []}
        for seed in a.seeds:
            t0 = time.perf_counter()
            f = features(inputs, fs, seed=seed)
            lay = {"seed": seed, "disks": len(f), "features_s": time.perf_counter() - t0}
            for split, runs in (("spatial", a.runs), ("blocks", a.block_runs)):
                t0 = time.perf_counter()
                kw = {"block_m": 5_000.0} if split == "blocks" else {}
                with estimator_options(ekw.get("estimator_options")):
                    ev = evaluate(f, split=split, runs=runs, feature_groups=False, small_classes="drop", rng=0,
                                  **kw, **{k: v for k, v in ekw.items() if k != "estimator_options"})
                lay[split] = ev.mean_accuracy
                lay[f"{split}_s"] = time.perf_counter() - t0
                lay[f"{split}_per_class"] = ev.per_class
                if split == "spatial":
                    lay["terrain"] = ev.terrain_accuracy
            lay["load"] = list(os.getloadavg())
            res["layouts"].append(lay)
        for k in ("spatial", "blocks", "terrain"):
            res[k] = float(np.mean([lay[k] for lay in res["layouts"]]))
        results.append(res)
        print(f"{title}: strip {100 * res['spatial']:.1f} %, blocks {100 * res['blocks']:.1f} %", flush=True)
    # rows not rerun keep their figures from the last record (same seeds and runs only)
    kept = []
    last = ROOT / "reports" / "benchmarks" / "classification_layouts.json"
    if a.rows is not None and last.exists():
        prev = json.loads(last.read_text())["results"]
        if prev["seeds"] == a.seeds and prev["runs"] == a.runs and prev["block_runs"] == a.block_runs:
            done = {r["variant"] for r in results}
            kept = [dict(r, kept=True) for r in prev["variants"] if r["variant"] not in done]
    order = {t[0]: i for i, t in enumerate(table)}
    results = sorted(kept + results, key=lambda r: order.get(r["variant"], len(order)))
    seeds = ", ".join(str(s) for s in a.seeds)
    lines = ["# The classifier's main choices over several disk layouts (R = 10 km, shared DEMs)", "",
             f"`python benchmarks/classification_layouts.py --seeds {' '.join(str(s) for s in a.seeds)} --runs "
             f"{a.runs} --block-runs {a.block_runs}"
             f"{'' if a.rows is None else ' --rows ' + ' '.join(str(i) for i in a.rows)}`: every row on the disk layouts drawn with seeds {seeds}. "
             f"Strip = held-out strip per region ({a.runs} runs), blocks = spatial k-fold with blocks of R/2 "
             f"({a.block_runs} run), training disks > 20 km from the held-out disks in both; terrain = share of "
             f"held-out strips whose disks together get the right region. Mean over the layouts, then the "
             f"figure of each layout. Extremely randomized trees (200) unless the row says otherwise. Rows marked "
             f"'earlier run' were not rerun (`--rows`): their figures come from the previous record with the same "
             f"seeds and runs.", "",
             "| variant | features | strip % (mean) | strip % per layout | blocks % (mean) | blocks % per layout "
             "| terrain % (mean) |", "|---|---:|---:|---|---:|---|---:|"]
    for r in results:
        s = " / ".join(f"{100 * lay['spatial']:.1f}" for lay in r["layouts"])
        b = " / ".join(f"{100 * lay['blocks']:.1f}" for lay in r["layouts"])
        lines.append(f"| {r['variant']}{' (earlier run)' if r.get('kept') else ''} | {r['n_features']} | "
                     f"{100 * r['spatial']:.1f} | {s} | "
                     f"{100 * r['blocks']:.1f} | {b} | {100 * r['terrain']:.1f} |")
    lines += ["", f"Load average at the end: {', '.join(f'{v:.1f}' for v in os.getloadavg())} (2 cores)."]
    write_text_atomic(a.out, "\n".join(lines) + "\n")
    record("classification_layouts", {"seeds": a.seeds, "runs": a.runs, "block_runs": a.block_runs,
                                      "variants": results})


if __name__ == "__main__":
    main()
