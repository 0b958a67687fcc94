"""Ablation of the region classifier on the shared DEMs: every choice, judged by the spatial hold-out.

Usage: python benchmarks/classification_ablation.py [--analysis-dir reports/analysis] [--runs 20]
       [--block-runs 2] [--out reports/classification/ablation.md]

Inputs are the ``orokit analyze`` folders of the 13 manifest DEMs (``make analysis``).
Each row changes one thing (feature set, disk layout, classifier) and is evaluated with
the same seeds: spatial hold-out (a strip of each region, training disks > 2 R away), the
spatial k-fold blocks (blocks of R/2, every disk held out once, training disks > 2 R from
the held-out block; ``--block-runs`` runs) and the paper's random 80:20 split, R = 10 km,
``--runs`` runs each. A second table gives,
per feature of the paper's set, the total-variation distance between the mean
histograms of the two halves (north / south disks) of one region, against the distance
between regions: features whose halves differ almost as much as regions do do not
transfer to unseen ground. Results go to ``--out`` (Markdown) and
``reports/benchmarks/classification_ablation.json`` (with timings and the machine load).
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def variants():
    from orokit.sampling.feature_sets import FeatureSet
    from orokit.sampling.histograms import HistogramSpec

    paper = FeatureSet.paper()
    spec = HistogramSpec.paper()
    nodir = tuple(n for n in spec.names if "direction" not in n)
    oro = FeatureSet.orometry()
    # the default until this ablation: R/2 and R, every histogram but the direction ones
    prev = dataclasses.replace(oro, name="v", radii=(0.5, 1.0), histograms=nodir)
    rows = [
        ("paper histograms, Random Forest (reference)", paper, {}, {"classifier": "rf"}),
        ("paper histograms, extremely randomized trees", paper, {}, {}),
        ("+ disk summaries", dataclasses.replace(paper, name="v", summaries=True), {}, {}),
        ("+ summaries, cumulative histograms", dataclasses.replace(paper, name="v", summaries=True,
                                                                   cumulative=True), {}, {}),
        ("+ summaries, cumulative, no direction histograms",
         dataclasses.replace(paper, name="v", summaries=True, cumulative=True, histograms=nodir), {}, {}),
        ("+ elevation summaries (R only)", dataclasses.replace(prev, name="v", radii=(1.0,)), {}, {}),
        ("+ radii R/2 and R (previous default)", prev, {}, {}),
        ("+ radii R/4, R/2, R", dataclasses.replace(prev, name="v", radii=(0.25, 0.5, 1.0)), {}, {}),
        ("R/2 and R, without the disk-relative histograms", dataclasses.replace(oro, name="v", radii=(0.5, 1.0)),
         {}, {}),
        ("orometry (default): R only, without the disk-relative histograms", oro, {}, {}),
        ("summaries + elevation only (no histograms)", dataclasses.replace(oro, name="v", histograms=()), {}, {}),
        ("orometry, denser disks (0.25 R apart, <= 400 per region, <= 400 training)", oro,
         {"separation": 0.25, "max_disks": 400}, {"max_train": 400}),
        ("orometry, another disk layout (seed 1)", oro, {"seed": 1}, {}),
        ("orometry, another disk layout (seed 2)", oro, {"seed": 2}, {}),
        ("+ spatial pattern (peak spacing, key-saddle alignment, steepness, elevation-prominence correlation)",
         dataclasses.replace(oro, name="v", pattern=True), {}, {}),
        ("summaries + elevation + spatial pattern (no histograms)",
         dataclasses.replace(oro, name="v", pattern=True, histograms=()), {}, {}),
        ("orometry, 100 extremely randomized trees (half)", oro, {}, {"n_estimators": 50}),
        ("orometry, Random Forest", oro, {}, {"classifier": "rf"}),
        ("orometry, gradient boosting (HistGradientBoosting)", oro, {}, {"classifier": "hgb"}),
    ]
    return rows


def features(inputs, fs, *, separation=0.5, max_disks=100, seed=0):
    from orokit.classify.features import concat_features
    from orokit.classify.inputs import features_for_input

    seeds = np.random.SeedSequence([seed, 10_000]).spawn(len(inputs))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tables = [features_for_input(p, radius_m=10_000.0, feature_set=fs, separation=separation,
                                     max_disks=max_disks, rng=np.random.default_rng(s)) for p, s in zip(inputs, seeds)]
    return concat_features(tables)


def tv_table(feats) -> list[dict]:
    """Per histogram feature: mean TV distance between the halves of a region vs between regions."""
    from orokit.classify.features import feature_set_of

    fs = feature_set_of(feats)
    out = []
    labels = [lab for lab, g in feats.groupby("label") if len(g) >= 6]
    for name, cols in fs.histogram_spec.groups().items():
        within, means = [], {}
        for lab in labels:
            g = feats[feats["label"] == lab]
            north = g["y"] >= g["y"].median()
            a, b = g.loc[north, cols].to_numpy().mean(0), g.loc[~north, cols].to_numpy().mean(0)
            within.append(0.5 * np.abs(a - b).sum())
            means[lab] = g[cols].to_numpy().mean(0)
        between = [0.5 * np.abs(means[p] - means[q]).sum() for i, p in enumerate(labels) for q in labels[i + 1:]]
        out.append({"feature": name, "tv_between_halves": float(np.mean(within)),
                    "tv_between_regions": float(np.mean(between)),
                    "ratio": float(np.mean(within) / np.mean(between))})
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--analysis-dir", type=Path, default=ROOT / "reports" / "analysis")
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--block-runs", type=int, default=2)
    ap.add_argument("--out", type=Path, default=ROOT / "reports" / "classification" / "ablation.md")
    a = ap.parse_args()
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from _record import record

    from orokit.classify.train import evaluate
    from orokit.io.atomic import write_text_atomic

    inputs = sorted(p for p in a.analysis_dir.iterdir() if (p / "analysis.json").exists())
    if len(inputs) < 2:
        raise SystemExit(f"{a.analysis_dir} holds no analysis folders; run `make analysis` first")
    rows = []
    for title, fs, fkw, ekw in variants():
        t0 = time.perf_counter()
        f = features(inputs, fs, **fkw)
        t_feat = time.perf_counter() - t0
        res = {"variant": title, "feature_set": fs.to_dict(), "n_features": len(fs.columns), "disks": len(f),
               **fkw, **ekw}
        for split in ("spatial", "random", "blocks"):
            t0 = time.perf_counter()
            kw = {"runs": a.block_runs, "block_m": 5_000.0} if split == "blocks" else {"runs": a.runs}
            ev = evaluate(f, split=split, feature_groups=False, small_classes="drop", rng=0, **kw, **ekw)
            res[split] = ev.mean_accuracy
            res[f"{split}_runs"] = ev.accuracies.tolist()
            res[f"{split}_s"] = time.perf_counter() - t0
            if split in ("spatial", "blocks"):
                res[f"{split}_per_class"] = ev.per_class
            if split == "spatial":
                res["terrain"] = ev.terrain_accuracy
        res["features_s"] = t_feat
        res["load"] = list(os.getloadavg())
        rows.append(res)
        print(f"{title}: spatial {100 * res['spatial']:.1f} %, blocks {100 * res['blocks']:.1f} %, "
              f"random {100 * res['random']:.1f} %, "
              f"terrain {100 * res['terrain']:.1f} % ({res['n_features']} features, {len(f)} disks)", flush=True)
    from orokit.sampling.feature_sets import FeatureSet

    tv = tv_table(features(inputs, FeatureSet.paper()))
    lines = ["# Ablation of the region classifier (R = 10 km, shared DEMs)", "",
             f"`python benchmarks/classification_ablation.py --runs {a.runs} --block-runs {a.block_runs}`: "
             f"each row changes one choice; "
             f"every row uses the same seeds. Spatial = held-out strip per region, training disks > 20 km away "
             f"(the figure every choice was made by); terrain = share of held-out strips whose disks together "
             f"(summed log-probability) get the right region; blocks = spatial k-fold, blocks of R/2, every disk "
             f"held out once, training disks > 20 km from the held-out block ({a.block_runs} runs; min-max over "
             f"the runs in brackets); random = the paper's 80:20 split. "
             f"Extremely randomized trees (200), <= 80 training disks per region and run, disks 0.5 R "
             f"apart, <= 100 per region, unless the row says otherwise; regions with < 2 disks dropped. "
             f"Disks placed with seed 0 unless the row says otherwise: the two 'another disk layout' rows show "
             f"how far the figures move with the placement of the disks alone.", "",
             "| variant | features | disks | spatial % | terrain % | blocks % | random % |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        b = np.asarray(r["blocks_runs"], dtype=float) * 100
        lines.append(f"| {r['variant']} | {r['n_features']} | {r['disks']} | {100 * r['spatial']:.1f} | "
                     f"{100 * r['terrain']:.1f} | {100 * r['blocks']:.1f} ({np.nanmin(b):.1f}-{np.nanmax(b):.1f}) | "
                     f"{100 * r['random']:.1f} |")
    lines += ["", f"Load average at the end: {', '.join(f'{v:.1f}' for v in os.getloadavg())} (2 cores).", "",
              "## Which histograms transfer", "",
              "Total-variation distance between the mean histograms of a region's north and south disks, against "
              "the mean distance between regions (paper features, regions with >= 6 disks). A ratio near 1 means "
              "the two halves of one region differ as much as two regions do.", "",
              "| feature | TV between halves | TV between regions | ratio |", "|---|---:|---:|---:|"]
    for t in sorted(tv, key=lambda t: -t["ratio"]):
        lines.append(f"| {t['feature']} | {t['tv_between_halves']:.3f} | {t['tv_between_regions']:.3f} | "
                     f"{t['ratio']:.2f} |")
    write_text_atomic(a.out, "\n".join(lines) + "\n")
    record("classification_ablation", {"runs": a.runs, "block_runs": a.block_runs, "variants": rows, "transfer": tv})


if __name__ == "__main__":
    main()
