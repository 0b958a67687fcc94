"""``orokit train``: the region classifier, evaluated with the paper's random split and a spatial hold-out."""
from __future__ import annotations

import json
from pathlib import Path

import click

from orokit.cli.options import overwrite_option, progress_option, seed_option


@click.command()
@click.argument("features_path", metavar="FEATURES.parquet", type=click.Path(exists=True, dir_okay=False,
                                                                           path_type=Path))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="Model file (.skops); metadata goes to OUTPUT.json beside it.")
@click.option("--runs", type=int, default=30, show_default=True,
              help="Evaluation runs, each with a fresh split (per region <= 80 training / 20 validation disks; paper: 100).")
@click.option("--feature-runs", type=int, default=0, show_default=True,
              help="Runs for the accuracy of each feature group alone (Table 2 rows; `orokit report` runs them); "
                   "0 skips them. Each run adds one fit per feature group and split: 5 runs more than double "
                   "the training time.")
@click.option("--split", type=click.Choice(["random", "spatial", "blocks", "both", "all"]), default="both",
              show_default=True,
              help="random: the paper's 80:20 split; spatial: a held-out strip of each region, training disks "
                   "farther than --buffer from it (honest when disks overlap); blocks: spatial k-fold, every "
                   "disk held out once with its block, training on all disks farther than --buffer; "
                   "both: random and spatial; all: the three.")
@click.option("--buffer", "buffer_radii", type=float, default=2.0, show_default=True,
              help="Spatial and block splits: minimum training-to-validation centre distance, in units of R "
                   "(2 = no shared peak).")
@click.option("--block", "block_radii", type=click.FloatRange(min=0.0, min_open=True), default=1.0,
              show_default=True, help="Block split: side of the square blocks, in units of R.")
@click.option("--classifier", type=click.Choice(["rf", "et", "hgb"]), default="et", show_default=True,
              help="et: extremely randomized trees, 2x --trees (default, chosen on the spatial hold-out); rf: the paper's Random Forest; hgb: scikit-learn HistGradientBoostingClassifier.")
@click.option("--trees", type=int, default=100, show_default=True,
              help="Trees of the forest (et uses twice as many; boosting iterations with --classifier hgb).")
@click.option("--max-train", type=int, default=80, show_default=True,
              help="At most this many training disks per region in each evaluation run (paper: 80).")
@click.option("--drop-small-classes", is_flag=True,
              help="Drop regions with fewer than 2 disks (with a warning) instead of failing.")
@click.option("--report", "report_dir", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Also write Table 2 (Markdown/CSV), confusion matrix and histogram figures to this folder.")
@click.option("--json", "as_json", is_flag=True,
              help="Print mean_accuracy, median_accuracy, per_class and per_feature accuracies as JSON.")
@click.option("--n-jobs", type=int, default=2, show_default=True, help="Parallel fits.")
@seed_option(what="the splits and the forests")
@overwrite_option("an existing model and report files")
@progress_option()
def train(features_path, output, runs, feature_runs, split, buffer_radii, block_radii, classifier, trees, max_train,
          drop_small_classes, report_dir, as_json, n_jobs, seed, overwrite, progress):
    """Train the region classifier on FEATURES.parquet (from `orokit features`) and evaluate it.

    Accuracies are fractions in [0, 1]. The saved model is fitted on all disks.
    """
    from orokit.classify.calibration import Calibration
    from orokit.classify.features import check_feature_table
    from orokit.classify.model import metadata_path, model_metadata, save_model
    from orokit.classify.train import evaluate, train_classifier
    from orokit.io.hashing import sha256_file
    from orokit.io.model_io import read_feature_table

    kinds = {"both": ["random", "spatial"], "all": ["random", "spatial", "blocks"]}.get(split, [split])
    feats = read_feature_table(features_path)
    check_feature_table(feats, name=str(features_path))
    radius = float(feats["radius_m"].max()) if len(feats) else 0.0
    outputs = [output, metadata_path(output)]
    if report_dir is not None:
        from orokit.reports.classification import training_report_files

        outputs += training_report_files(radius, kinds, report_dir)
    from orokit.cli.outputs import claim_outputs

    claim_outputs(output, report_dir)  # locked for the whole run
    existing = [str(p) for p in outputs if p.exists()]
    if existing and not overwrite:  # checked before the (long) training runs
        raise click.UsageError(f"{', '.join(existing)} exist(s); pass --overwrite to replace them")
    small = "drop" if drop_small_classes else "error"
    if drop_small_classes:
        counts = feats["label"].astype(str).value_counts()
        dropped = counts[counts < 2]
        if len(dropped):
            click.echo("dropping regions with fewer than 2 usable disks: "
                       + ", ".join(f"{k}: {v}" for k, v in dropped.items()), err=True)
    evals = {}
    for kind in kinds:
        evals[kind] = evaluate(feats, runs=runs, split=kind, feature_groups=feature_runs > 0,
                               feature_runs=feature_runs, n_estimators=trees, buffer_m=buffer_radii * radius,
                               block_m=block_radii * radius,
                               max_train=max_train, classifier=classifier, small_classes=small, n_jobs=n_jobs,
                               progress=progress, rng=seed)
    model = train_classifier(feats, n_estimators=trees, small_classes=small, classifier=classifier, n_jobs=n_jobs,
                             rng=seed)
    cal = evals["spatial"].calibration() if "spatial" in evals else Calibration()
    summary = {k: {kk: v for kk, v in e.to_dict().items() if kk != "confusion"} for k, e in evals.items()}
    md = model_metadata(model, feats, evaluation=summary, features_sha256=sha256_file(features_path),
                        extra={"training_features": features_path.name, "seed": seed, "classifier": classifier,
                               "calibration": cal.to_dict()})
    save_model(model, output, md)
    if report_dir is not None:
        from orokit.reports.classification import write_training_report

        write_training_report(feats, evals, report_dir)
    main = evals.get("random") or next(iter(evals.values()))
    if as_json:
        out = {"mean_accuracy": main.mean_accuracy, "median_accuracy": main.median_accuracy,
               "per_class": main.per_class, "per_feature": main.per_feature, "split": main.split,
               "runs": runs, "model": str(output)}
        for k in ("spatial", "blocks"):
            if k in evals and main.split != k:
                s = evals[k]
                out[k] = {"mean_accuracy": s.mean_accuracy, "median_accuracy": s.median_accuracy,
                          "per_class": s.per_class, "per_feature": s.per_feature}
        click.echo(json.dumps(out, indent=2))
    else:
        for k, e in evals.items():
            click.echo(f"{k} split, {runs} runs: mean accuracy {100 * e.mean_accuracy:.1f} %, median "
                       f"{100 * e.median_accuracy:.1f} %")
        click.echo(f"model ({len(model.classes_)} classes, {len(feats)} disks) -> {output}")
