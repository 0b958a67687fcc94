"""Classification report: Table 2 (Markdown/CSV), confusion matrices, per-region histograms.

Layout of a report folder::

    README.md                      the numbers in words
    manifest.json                  inputs (with sha256), orokit version, seed, parameters
    tables/table2.md, table2.csv   accuracy (%) per radius: overall and per feature group
    tables/per_class_<R>km.csv     per-region accuracy, random and spatial split, disks used
    tables/evaluation_<R>km.json   full evaluation (accuracies per run, confusion counts)
    figures/confusion_<split>_<R>km.png
    figures/histograms_<R>km.png   mean histogram of every feature per region (paper Fig. 7)
    features/features_<R>km.parquet
"""
from __future__ import annotations

import json
import logging
import os
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from orokit import __version__
from orokit._typing import PathLike
from orokit.sampling.feature_sets import SUMMARY_TITLES
from orokit.sampling.histograms import FEATURE_TITLES, HistogramSpec

if TYPE_CHECKING:  # pragma: no cover
    from orokit.classify.train import ClassifierKind

TITLES = {**FEATURE_TITLES, **SUMMARY_TITLES}

logger = logging.getLogger(__name__)
DPI = 110


def _km(r: float) -> str:
    return f"{r / 1000:g} km"


def table2(evals: Mapping[float, Mapping[str, Any]]) -> pd.DataFrame:
    """Table 2 layout: accuracy in % per radius (columns) for the whole feature vector and
    for each feature group alone (random split), plus the spatially held-out figures."""
    cols = {}
    for r in sorted(evals):
        e = evals[r]
        col: dict[str, float] = {}
        if "random" in e:
            col["All, mean acc."] = 100 * e["random"].mean_accuracy
            col["All, median acc."] = 100 * e["random"].median_accuracy
        if "spatial" in e:
            col["All, mean acc. (spatial hold-out)"] = 100 * e["spatial"].mean_accuracy
            col["All, median acc. (spatial hold-out)"] = 100 * e["spatial"].median_accuracy
        if "blocks" in e:
            col["All, mean acc. (spatial k-fold blocks)"] = 100 * e["blocks"].mean_accuracy
        base = e["random"] if "random" in e else e["spatial"]
        for name, acc in base.per_feature.items():
            col[TITLES.get(name, name)] = 100 * acc
        if "spatial" in e and "random" in e:
            for name, acc in e["spatial"].per_feature.items():
                col[f"{TITLES.get(name, name)} (spatial)"] = 100 * acc
        col["Regions"] = len(base.classes)
        col["Disks"] = base.params["n_disks"]
        cols[_km(r)] = col
    return pd.DataFrame(cols)


def to_markdown(df: pd.DataFrame, *, floatfmt: str = ".1f") -> str:
    """A pipe table (no tabulate dependency)."""
    head = "| |" + "|".join(f" {c} " for c in df.columns) + "|"
    sep = "|---|" + "|".join("---:" for _ in df.columns) + "|"
    lines = [head, sep]
    for idx, row in df.iterrows():
        cells = []
        for v in row:
            if isinstance(v, (float, np.floating)):
                cells.append(" - " if not np.isfinite(v) else
                             (f" {int(v)} " if float(v).is_integer() and abs(float(v)) >= 100 else f" {v:{floatfmt}} "))
            else:
                cells.append(f" {v} ")
        lines.append(f"| {idx} |" + "|".join(cells) + "|")
    return "\n".join(lines) + "\n"


def plot_confusion(ax: Any, confusion: np.ndarray, classes: Sequence[str], *, title: str | None = None) -> Any:
    """Row-normalized confusion matrix (true class in rows) as an image with percentages."""
    c = np.asarray(confusion, dtype=float)
    s = c.sum(axis=1, keepdims=True)
    n = np.divide(c, s, out=np.zeros_like(c), where=s > 0)
    ax.imshow(n, cmap="Blues", vmin=0, vmax=1)
    ax.set_xticks(range(len(classes)), classes, rotation=60, ha="right", fontsize=7)
    ax.set_yticks(range(len(classes)), classes, fontsize=7)
    ax.set_xlabel("predicted")
    ax.set_ylabel("true")
    for i in range(len(classes)):
        for j in range(len(classes)):
            if n[i, j] >= 0.005:
                ax.text(j, i, f"{100 * n[i, j]:.0f}", ha="center", va="center", fontsize=6,
                        color="white" if n[i, j] > 0.6 else "black")
    if title:
        ax.set_title(title, fontsize=9)
    return ax


def plot_region_histograms(fig: Any, features: pd.DataFrame, spec: HistogramSpec,
                           labels: Sequence[str] | None = None) -> Any:
    """Mean histogram of each feature (columns) for each region (rows), paper Fig. 7 style."""
    labels = list(labels or sorted(features["label"].astype(str).unique()))
    feats = spec.features
    axes = fig.subplots(len(labels), len(feats), squeeze=False, sharey="col")
    for i, lab in enumerate(labels):
        sub = features[features["label"].astype(str) == lab]
        for j, fb in enumerate(feats):
            ax = axes[i, j]
            vals = sub[fb.columns].to_numpy(float).mean(axis=0) if len(sub) else np.zeros(fb.n_bins)
            ax.bar(np.arange(fb.n_bins), vals, width=0.9, color=f"C{j % 10}")
            ax.set_xticks([])
            ax.tick_params(labelsize=5)
            if i == 0:
                ax.set_title(FEATURE_TITLES.get(fb.name, fb.name), fontsize=6)
            if j == 0:
                ax.set_ylabel(f"{lab}\n(n={len(sub)})", fontsize=6, rotation=0, ha="right", va="center")
    return axes


def _save(fig: Any, path: Path) -> None:
    from orokit.io.atomic import atomic_path

    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=DPI, bbox_inches="tight", format=path.suffix.lstrip("."))


def _write_text(path: Path, text: str) -> None:
    from orokit.io.atomic import write_text_atomic

    path.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(path, text)


def write_radius_outputs(features: pd.DataFrame, evals: Mapping[str, Any], outdir: PathLike) -> dict[str, Path]:
    """Per-radius files: per-class table, evaluation JSON, confusion and histogram figures."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    out = Path(outdir)
    r = float(features["radius_m"].max())
    tag = f"{r / 1000:g}km"
    files: dict[str, Path] = {}
    base = evals.get("random") or next(iter(evals.values()))
    rows = []
    for c in base.classes:
        row = {"region": c, "disks": int((features["label"].astype(str) == c).sum())}
        for k, e in evals.items():
            row[f"{k}_accuracy_%"] = 100 * e.per_class.get(c, float("nan"))
            row[f"{k}_mean_train_disks"] = e.mean_train.get(c, float("nan"))
            row[f"{k}_mean_validation_disks"] = e.mean_val.get(c, float("nan"))
        rows.append(row)
    pc = pd.DataFrame(rows)
    files["per_class"] = out / "tables" / f"per_class_{tag}.csv"
    _write_text(files["per_class"], pc.to_csv(index=False, float_format="%.2f"))
    files["evaluation"] = out / "tables" / f"evaluation_{tag}.json"
    _write_text(files["evaluation"], json.dumps(
        {k: {**e.to_dict(), "accuracies": e.accuracies.tolist()} for k, e in evals.items()}, indent=1, default=float))
    for k, e in evals.items():
        n = len(e.classes)
        fig, ax = plt.subplots(figsize=(2 + 0.45 * n, 1.5 + 0.45 * n))
        plot_confusion(ax, e.confusion, e.classes,
                       title=f"{k} split, R = {_km(r)}, {len(e.accuracies)} runs: {100 * e.mean_accuracy:.1f} %")
        files[f"confusion_{k}"] = out / "figures" / f"confusion_{k}_{tag}.png"
        _save(fig, files[f"confusion_{k}"])
        plt.close(fig)
    from orokit.classify.features import feature_set_of

    spec = feature_set_of(features).histogram_spec
    labels = sorted(features["label"].astype(str).unique())
    fig = plt.figure(figsize=(14, 0.8 + 0.75 * len(labels)))
    plot_region_histograms(fig, features, spec, labels)
    fig.suptitle(f"Mean orometric histograms per region, R = {_km(r)}", fontsize=9)
    files["histograms"] = out / "figures" / f"histograms_{tag}.png"
    _save(fig, files["histograms"])
    plt.close(fig)
    return files


def training_report_files(radius_m: float, splits: Sequence[str], outdir: PathLike) -> list[Path]:
    """Every file :func:`write_training_report` writes for this radius and these splits
    (so a command can refuse to overwrite them before any work)."""
    out = Path(outdir)
    tag = f"{float(radius_m) / 1000:g}km"
    files = [out / "tables" / f"per_class_{tag}.csv", out / "tables" / f"evaluation_{tag}.json"]
    files += [out / "figures" / f"confusion_{k}_{tag}.png" for k in splits]
    files += [out / "figures" / f"histograms_{tag}.png", out / "tables" / "table2.csv", out / "tables" / "table2.md"]
    return files


def write_training_report(features: pd.DataFrame, evals: Mapping[str, Any], outdir: PathLike) -> Path:
    """Report of one ``orokit train`` run (one radius)."""
    out = Path(outdir)
    r = float(features["radius_m"].max())
    write_radius_outputs(features, evals, out)
    t2 = table2({r: evals})
    _write_text(out / "tables" / "table2.csv", t2.to_csv(float_format="%.2f"))
    _write_text(out / "tables" / "table2.md", to_markdown(t2))
    return out


_CLASSIFIERS = {"rf": "Random Forest, {n} trees", "et": "extremely randomized trees (ExtraTrees), 2 x {n} trees",
                "hgb": "gradient boosting (HistGradientBoosting), {n} iterations"}
_FEATURE_SETS = {"paper": "the paper's Table 1 histograms at R ({n} numbers, `--features paper`, reference mode)",
                 "orometry": "orokit's default (`--features orometry`, {n} numbers), at R: five Table 1 histograms "
                             "made cumulative (dominance, dominance groups, isolation distance, key-saddle distance, "
                             "prominence; the direction and disk-relative histograms left out); disk summaries "
                             "(peak density, prominence spectrum, maximum and quantiles of prominence, isolation, "
                             "key-saddle distance, dominance); quantiles of peak and key-saddle elevation; the key "
                             "saddles against their peaks (relief peaks to key saddles, col ratio, key-saddle height "
                             "in the disk). Chosen on the spatial hold-out: see `ablation.md` and `layouts.md` (mean "
                             "over three disk layouts)",
                 "terrain": "orokit's default for inputs with a DEM (`--features terrain`, `auto` on DEMs; {n} "
                            "numbers): the `orometry` set (five Table 1 histograms at R made cumulative, disk "
                            "summaries, peak and key-saddle elevation quantiles, the key saddles against their "
                            "peaks) plus the DEM's terrain in each disk (slope quantiles and flat share, local "
                            "relief in ~1 and ~5 km windows, Laplacian curvature, hypsometry in the disk, spectral "
                            "slope, share of cells draining > 1 km2). Chosen on the spatial hold-out over three "
                            "disk layouts: see `layouts.md`; peak lists use `orometry`"}


def _readme(t2: pd.DataFrame, evals: Mapping[float, Mapping[str, Any]], meta: dict[str, Any]) -> str:
    clf = _CLASSIFIERS.get(meta.get("classifier", "rf"), "{n}").format(n=meta["trees"])
    fs = meta.get("feature_set", "paper")
    lines = [f"# Region classification report (orokit, features: {fs})", "",
             f"orokit {__version__}; {meta['n_inputs']} DEMs ({', '.join(meta['labels'])}); "
             f"eps = {meta['min_prominence_m']:g} m; disks with < {meta['min_peaks']} peaks skipped; "
             f"at most {meta['max_disks']} disks per region, centres >= {meta.get('separation', 0.5):g} R apart; "
             f"at most {meta.get('max_train', 80)} training disks per region and run; {clf}; {meta['runs']} runs "
             f"(feature groups: {meta['feature_runs']} runs); seed {meta['seed']}.", "",
             f"Features: {_FEATURE_SETS.get(fs, fs).format(n=meta.get('n_features', '?'))}.", "",
             "Elevations: SRTM-3 void-filled by Jonathan de Ferranti (viewfinderpanoramas.org), crops from "
             "Argudo et al. (2019), github.com/oargudo/orometry-terrains (MIT). The crops have no published "
             "location: they are analysed as local metric grids.", "",
             "## Results", ""]
    for r in sorted(evals):
        e = evals[r]
        s = [f"- **R = {_km(r)}**:"]
        if "random" in e:
            rnd = e["random"]
            s.append(f"random 80:20 split (paper protocol) mean accuracy **{100 * rnd.mean_accuracy:.1f} %** "
                     f"(median {100 * rnd.median_accuracy:.1f} %)")
        if "spatial" in e:
            sp = e["spatial"]
            if np.isfinite(sp.mean_accuracy):
                s.append(f"; spatially held-out strip (training disks > {sp.params['buffer_m'] / 1000:g} km from "
                         f"validation disks) **{100 * sp.mean_accuracy:.1f} %** (median "
                         f"{100 * sp.median_accuracy:.1f} %)")
            else:
                s.append(f"; spatially held-out strip: **not measurable** (no run left every region a training "
                         f"disk > {sp.params['buffer_m'] / 1000:g} km from its held-out disks: the crops are too "
                         f"small for this radius)")
        if "blocks" in e and np.isfinite(e["blocks"].mean_accuracy):
            b = e["blocks"]
            s.append(f"; spatial k-fold (blocks of {b.params['block_m'] / 1000:g} km, every disk held out once, "
                     f"training disks > {b.params['buffer_m'] / 1000:g} km from the held-out block) "
                     f"**{100 * b.mean_accuracy:.1f} %** (spread over {len(b.accuracies)} runs: "
                     f"{100 * np.nanmin(b.accuracies):.1f}-{100 * np.nanmax(b.accuracies):.1f} %)")
        base = e["random"] if "random" in e else e["spatial"]
        s.append(f"; {len(base.classes)} regions, {base.params['n_disks']} disks")
        if base.params.get("dropped_classes"):
            s.append(f"; dropped (< 2 disks): {', '.join(base.params['dropped_classes'])}")
        absent = sorted(set(meta["labels"]) - set(base.classes) - set(base.params.get("dropped_classes", [])))
        if absent:
            s.append(f"; no disk with >= {meta['min_peaks']} peaks: {', '.join(absent)}")
        if "spatial" in e:
            n0 = int(np.sum(~np.isfinite(e["spatial"].accuracies)))
            if n0:
                s.append(f"; {n0} of {len(e['spatial'].accuracies)} spatial runs left a region without a "
                         f"training disk and are not counted")
        lines.append(" ".join(s) + ".")
        worst = sorted(base.per_class.items(), key=lambda kv: kv[1])[:3]
        lines.append("  Lowest per-region accuracy (random split): " +
                     ", ".join(f"{k} {100 * v:.0f} %" for k, v in worst) + ".")
        if "spatial" in e and np.isfinite(e["spatial"].mean_accuracy):
            sp = e["spatial"]
            worst = sorted(sp.per_class.items(), key=lambda kv: kv[1])[:3]
            lines.append("  Lowest per-region accuracy (spatial hold-out): " +
                         ", ".join(f"{k} {100 * v:.0f} %" for k, v in worst) + f". Terrain level (the held-out "
                         f"disks of a region together, summed log-probability): {100 * sp.terrain_accuracy:.1f} % "
                         f"of {len(sp.terrain)} held-out strips right.")
            if r == meta["radii_m"][0] and len(sp.heldout_true):
                cal = sp.calibration()
                lines.append(f"  Calibrated probabilities (temperature {cal.temperature:.2f} on the disks, "
                             f"{cal.terrain_temperature:.2f} on the terrain posterior, fitted on the spatial hold-out) "
                             f"and 'unknown' thresholds keeping 95 % of the right held-out answers (disk "
                             f"{cal.disk_threshold:.2f}, terrain {cal.terrain_threshold:.2f}): `calibration.md`.")
        if "blocks" in e and np.isfinite(e["blocks"].mean_accuracy):
            b = e["blocks"]
            worst = sorted(b.per_class.items(), key=lambda kv: kv[1])[:4]
            strip = (f" (held-out strip: {np.mean(list(e['spatial'].mean_train.values())):.1f})"
                     if "spatial" in e else "")
            lines.append("  Lowest per-region accuracy (k-fold blocks): "
                         + ", ".join(f"{k} {100 * v:.0f} %" for k, v in worst)
                         + f"; mean training disks per region and fold "
                           f"{np.mean(list(b.mean_train.values())):.1f}{strip}.")
    lines += ["", "Reference: the paper's published code on these DEMs at R = 10 km (20 runs, random 80:20 "
              "split) reaches 94 % mean accuracy (pyrenees 59 %, andes-chile 20 % with 3 usable disks).", "",
              "The random split puts overlapping neighbours of each validation disk in the training set "
              "(centres can be 0.5 R apart), so it flatters the score; the spatial figure holds out a strip "
              "of each region and trains only on disks that share no peak with it. The k-fold blocks cut each "
              "DEM into square blocks, hold out every block once and train on every disk farther than the "
              "buffer from it, so each disk is tested once and training keeps more of the DEM; the strip "
              "figure is kept for comparison with earlier reports.", "",
              "## Table 2 (accuracy, %)", "", to_markdown(t2), "",
              "Figures: `figures/confusion_*`, `figures/histograms_*`; per-region numbers: `tables/per_class_*`."]
    return "\n".join(lines) + "\n"


def build_classification_report(inputs: Sequence[PathLike], outdir: PathLike, *, radii_m: Sequence[float] = (10_000.0,),
                                runs: int = 100, feature_runs: int = 20, min_prominence_m: float = 30.0,
                                min_peaks: int = 20, max_disks: int = 100, trees: int = 100, seed: int = 0,
                                labels: Sequence[str] | None = None, model_path: PathLike | None = None,
                                model_radius_m: float | None = None, n_jobs: int = 2, progress: bool = False,
                                z_units: str | None = None, cell_size_m: float | None = None,
                                feature_set: str = "orometry", classifier: ClassifierKind = "et", separation: float = 0.5,
                                max_train: int = 80, block_runs: int = 0, block_m: float | None = None
                                ) -> dict[str, Any]:
    """Features -> repeated training runs -> Table 2, figures and README for several radii.

    ``inputs`` are DEMs, ``orokit analyze`` folders or peak lists (one region each).
    With ``model_path``, a model trained on all disks at ``model_radius_m`` (default the
    first radius) is saved there (skops + metadata). ``block_runs`` > 0 adds the spatial
    k-fold block split (:func:`orokit.classify.train.block_folds`, blocks of ``block_m``,
    default R / 2) with that many runs, without feature-group rows. Returns the tables, the
    evaluations per radius, the feature tables (``features``) and the metadata.
    """
    from orokit.classify.inputs import default_label
    from orokit.io.fetch import sha256_file
    from orokit.io.model_io import write_feature_table
    from orokit.classify.train import evaluate

    from orokit.sampling.feature_sets import FeatureSet

    fset = FeatureSet.named(feature_set)
    out = Path(outdir)
    labels = list(labels) if labels else [default_label(p) for p in inputs]
    evals: dict[float, dict[str, Any]] = {}
    timings: dict[str, float] = {}
    feats_by_r: dict[float, pd.DataFrame] = {}
    for r in radii_m:
        t0 = time.perf_counter()
        feats = _region_features(inputs, labels, radius_m=r, seed=seed, min_prominence_m=min_prominence_m,
                                 min_peaks=min_peaks, max_disks=max_disks, z_units=z_units, cell_size_m=cell_size_m,
                                 feature_set=feature_set, separation=separation)
        timings[f"features_{r / 1000:g}km_s"] = time.perf_counter() - t0
        write_feature_table(feats, out / "features" / f"features_{r / 1000:g}km.parquet")
        feats_by_r[r] = feats
        evals[r] = {}
        for kind in ("random", "spatial"):
            t0 = time.perf_counter()
            evals[r][kind] = evaluate(feats, runs=runs, split=kind, feature_runs=feature_runs, n_estimators=trees,
                                      max_train=max_train, classifier=classifier, small_classes="drop",
                                      n_jobs=n_jobs, progress=progress, rng=seed)
            timings[f"train_{kind}_{r / 1000:g}km_s"] = time.perf_counter() - t0
        if block_runs > 0:
            t0 = time.perf_counter()
            evals[r]["blocks"] = evaluate(feats, runs=block_runs, split="blocks", feature_groups=False,
                                          n_estimators=trees, max_train=max_train, classifier=classifier,
                                          block_m=block_m or 0.5 * r, small_classes="drop", n_jobs=n_jobs,
                                          progress=progress, rng=seed)
            timings[f"train_blocks_{r / 1000:g}km_s"] = time.perf_counter() - t0
        write_radius_outputs(feats, evals[r], out)
    t2 = table2(evals)
    _write_text(out / "tables" / "table2.csv", t2.to_csv(float_format="%.2f"))
    _write_text(out / "tables" / "table2.md", to_markdown(t2))
    meta = {"orokit_version": __version__, "n_inputs": len(inputs), "labels": labels, "seed": seed, "runs": runs,
            "feature_runs": feature_runs, "radii_m": list(map(float, radii_m)), "min_prominence_m": min_prominence_m,
            "min_peaks": min_peaks, "max_disks": max_disks, "trees": trees,
            "feature_set": feature_set, "n_features": len(fset.columns), "classifier": classifier, "separation": separation,
            "max_train": max_train, "block_runs": block_runs,
            "inputs": [str(p) for p in inputs]}
    if model_path is not None:
        rm = model_radius_m or radii_m[0]
        _save_region_model(feats_by_r[rm], evals[rm], model_path, out / "features" / f"features_{rm / 1000:g}km.parquet",
                           labels=labels, seed=seed, trees=trees, classifier=classifier, n_jobs=n_jobs)
        meta["model"] = {"path": str(model_path), "sha256": sha256_file(model_path), "radius_m": rm}
    _write_text(out / "manifest.json", json.dumps(meta, indent=2, default=float))
    # timings change with the machine's load: kept out of the committed manifest (timings.json is not committed)
    _write_text(out / "timings.json", json.dumps({"timings_s": timings, "load_average": os.getloadavg()}, indent=2))
    _write_text(out / "README.md", _readme(t2, evals, meta))
    return {"table2": t2, "evaluations": evals, "features": feats_by_r, "meta": meta}


def _region_features(inputs: Sequence[PathLike], labels: Sequence[str], *, radius_m: float, seed: int,
                     feature_set: str, **kw: Any) -> pd.DataFrame:
    """Feature table of all inputs at one radius; input k's disks come from seed ``[seed, R]``'s k-th child,
    so a radius' disks do not depend on the other radii of the run."""
    import warnings

    from orokit.classify.features import concat_features
    from orokit.classify.inputs import features_for_input
    from orokit.errors import OrokitWarning
    from orokit.sampling.feature_sets import FeatureSet

    fset = FeatureSet.named(feature_set)
    seeds = np.random.SeedSequence([seed, int(radius_m)]).spawn(len(inputs))
    tables = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", OrokitWarning)
        for src, lab, s in zip(inputs, labels, seeds):
            tables.append(features_for_input(src, radius_m=radius_m, label=lab, feature_set=fset,
                                             rng=np.random.default_rng(s), **kw))
    for w in caught:
        logger.info("%s", w.message)
    return concat_features(tables)


def _save_region_model(feats: pd.DataFrame, evals: Mapping[str, Any], model_path: PathLike, features_path: Path, *,
                       labels: Sequence[str], seed: int, trees: int, classifier: ClassifierKind, n_jobs: int) -> None:
    """Fit the forest on all disks of ``feats`` and save it with the calibration of ``evals['spatial']``
    (identity without it) and the evaluations' summaries."""
    from orokit.classify.calibration import Calibration
    from orokit.classify.model import model_metadata, save_model
    from orokit.classify.train import train_classifier
    from orokit.io.fetch import sha256_file

    model = train_classifier(feats, n_estimators=trees, small_classes="drop", classifier=classifier,
                             n_jobs=n_jobs, rng=seed)
    sp = evals.get("spatial")
    cal = sp.calibration() if sp is not None else Calibration()
    summary = {k: {kk: v for kk, v in e.to_dict().items() if kk != "confusion"} for k, e in evals.items()}
    md = model_metadata(model, feats, evaluation=summary, features_sha256=sha256_file(features_path),
                        extra={"training_features": features_path.name, "seed": seed,
                               "training_inputs": list(labels), "classifier": classifier,
                               "calibration": cal.to_dict()})
    save_model(model, model_path, md)


def build_region_model(inputs: Sequence[PathLike], model_path: PathLike, features_dir: PathLike, *,
                       radius_m: float = 10_000.0, runs: int = 30, min_prominence_m: float = 30.0,
                       min_peaks: int = 20, max_disks: int = 100, trees: int = 100, seed: int = 0,
                       labels: Sequence[str] | None = None, n_jobs: int = 2, progress: bool = False,
                       z_units: str | None = None, cell_size_m: float | None = None, feature_set: str = "orometry",
                       classifier: ClassifierKind = "et", separation: float = 0.5, max_train: int = 80
                       ) -> dict[str, Any]:
    """The model :func:`build_classification_report` saves with ``model_path``, without the report.

    The same disks (seed), the spatial hold-out its calibration comes from (``runs`` runs, no
    feature-group rows, no random split) and the same forest: its predictions equal the
    report's model's; only the metadata's ``evaluation`` holds the spatial split alone. The
    feature table goes to ``features_dir/features_<R>km.parquet``. Returns that evaluation.
    """
    from orokit.classify.inputs import default_label
    from orokit.classify.train import evaluate
    from orokit.io.model_io import write_feature_table

    labels = list(labels) if labels else [default_label(p) for p in inputs]
    feats = _region_features(inputs, labels, radius_m=radius_m, seed=seed, min_prominence_m=min_prominence_m,
                             min_peaks=min_peaks, max_disks=max_disks, z_units=z_units, cell_size_m=cell_size_m,
                             feature_set=feature_set, separation=separation)
    fpath = write_feature_table(feats, Path(features_dir) / f"features_{radius_m / 1000:g}km.parquet")
    spatial = evaluate(feats, runs=runs, split="spatial", feature_groups=False, n_estimators=trees,
                       max_train=max_train, classifier=classifier, small_classes="drop", n_jobs=n_jobs,
                       progress=progress, rng=seed)
    _save_region_model(feats, {"spatial": spatial}, model_path, fpath, labels=labels, seed=seed, trees=trees,
                       classifier=classifier, n_jobs=n_jobs)
    return {"spatial": spatial}
