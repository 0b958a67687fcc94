"""``orokit report``: the classification report (Table 2, confusion matrices, histograms)."""
from __future__ import annotations

from pathlib import Path

import click

from orokit.cli.options import (
    RADIUS,
    cell_size_option,
    min_prominence_option,
    overwrite_option,
    progress_option,
    seed_option,
    z_units_option,
)


@click.command()
@click.argument("inputs", nargs=-1, type=click.Path(exists=True, path_type=Path))
@click.option("--analysis-dir", type=click.Path(exists=True, file_okay=False, path_type=Path), default=None,
              help="Folder of `orokit analyze` outputs, one sub-folder per region (used when no INPUT is given).")
@click.option("-o", "--output", type=click.Path(file_okay=False, path_type=Path),
              default=Path("reports/classification"), show_default=True, help="Report folder.")
@click.option("--radius", "radii", type=RADIUS, multiple=True,
              help="Disk radius with unit; repeat for several (default 10km, 5km, 15km).")
@click.option("--runs", type=int, default=100, show_default=True, help="Training runs with fresh splits.")
@click.option("--feature-runs", type=int, default=20, show_default=True, help="Runs per feature group (Table 2 rows).")
@min_prominence_option()
@click.option("--min-peaks", type=int, default=20, show_default=True, help="Skip disks with fewer peaks.")
@click.option("--model", "model_path", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Also save a model trained on all disks at the first radius (e.g. models/regions-10km.skops).")
@click.option("--model-only", is_flag=True,
              help="Write only --model (`make region-model`): the features at the first radius (into "
                   "OUTPUT/features/), the spatial hold-out of --runs runs its calibration comes from, and the "
                   "forest; the same predictions as the report's model, without the report's other runs.")
@z_units_option(help="Elevation units of DEM inputs that do not declare them (PNG).")
@cell_size_option(help="Cell size of DEM inputs without georeference (PNG)")
@click.option("--features", "feature_set", type=click.Choice(["orometry", "terrain", "paper"]), default="orometry",
              show_default=True, help="Feature set (paper: Argudo et al. 2019 Table 1, the reference mode).")
@click.option("--classifier", type=click.Choice(["rf", "et", "hgb"]), default="et", show_default=True,
              help="et: extremely randomized trees, 2x --trees (default, chosen on the spatial hold-out); rf: the paper's Random Forest; hgb: HistGradientBoostingClassifier.")
@click.option("--separation", type=float, default=0.5, show_default=True,
              help="Minimum disk-centre distance as a fraction of R.")
@click.option("--max-disks", type=int, default=100, show_default=True, help="At most this many disks per region.")
@click.option("--max-train", type=int, default=80, show_default=True,
              help="At most this many training disks per region in each run (paper: 80).")
@click.option("--block-runs", type=click.IntRange(min=0), default=0, show_default=True,
              help="Also evaluate the spatial k-fold block split (blocks of R/2, every disk held out once) with "
                   "this many runs; 0 skips it.")
@click.option("--open-set-runs", type=click.IntRange(min=0), default=0, show_default=True,
              help="Also test the 'unknown' answer by leaving each region out of training in turn, with this many "
                   "runs per region (calibration.md); 0 skips it.")
@seed_option(what="the disks, the splits and the forests")
@click.option("--n-jobs", type=int, default=2, show_default=True, help="Parallel fits.")
@overwrite_option("an existing report and model")
@progress_option()
def report(inputs, analysis_dir, output, radii, runs, feature_runs, min_prominence_m, min_peaks, model_path, model_only,
           z_units, cell_size_m, feature_set, classifier, separation, max_disks, max_train, block_runs, open_set_runs, seed,
           n_jobs, overwrite, progress):
    """Classification report on INPUTs (DEMs, analysis folders or peak lists; one region each).

    Accuracies in the tables are percentages; radii in km.
    """
    from orokit.reports.classification import build_classification_report

    if not inputs:
        if analysis_dir is None:
            raise click.UsageError("give INPUTs or --analysis-dir")
        inputs = sorted(p for p in analysis_dir.iterdir() if (p / "peaks.parquet").exists())
        if not inputs:
            raise click.UsageError(f"{analysis_dir} holds no analysis folder (sub-folders with peaks.parquet)")
    from orokit.cli.outputs import claim_outputs

    if model_only and model_path is None:
        raise click.UsageError("--model-only needs --model MODEL.skops (the file to write)")
    claim_outputs(output, model_path)  # locked for the whole run
    if (output / "README.md").exists() and not overwrite and not model_only:
        raise click.UsageError(f"{output} already holds a report; pass --overwrite to replace it")
    if model_path is not None and model_path.exists() and not overwrite:
        raise click.UsageError(f"{model_path} exists; pass --overwrite to replace it")
    radii = list(radii) or [10_000.0, 5_000.0, 15_000.0]
    if model_only:
        from orokit.reports.classification import build_region_model

        ev = build_region_model(list(inputs), model_path, output / "features", radius_m=radii[0], runs=runs,
                                min_prominence_m=min_prominence_m, min_peaks=min_peaks, max_disks=max_disks,
                                n_jobs=n_jobs, progress=progress, seed=seed, z_units=z_units, cell_size_m=cell_size_m,
                                feature_set=feature_set, classifier=classifier, separation=separation,
                                max_train=max_train)["spatial"]
        click.echo(f"R = {radii[0] / 1000:g} km: spatial hold-out {100 * ev.mean_accuracy:.1f} % ({runs} runs); "
                   f"model -> {model_path}")
        return
    res = build_classification_report(list(inputs), output, radii_m=radii, runs=runs, feature_runs=feature_runs,
                                      min_prominence_m=min_prominence_m, min_peaks=min_peaks, model_path=model_path,
                                      n_jobs=n_jobs, progress=progress, seed=seed, z_units=z_units,
                                      cell_size_m=cell_size_m, feature_set=feature_set, classifier=classifier,
                                      separation=separation, max_disks=max_disks, max_train=max_train,
                                      block_runs=block_runs)
    r0 = radii[0]
    spatial = res["evaluations"][r0].get("spatial")
    if spatial is not None and len(spatial.heldout_true):  # calibration.md: calibration and open-set test at R0
        from orokit.classify.train import evaluate_open_set
        from orokit.reports.classification_calibration import write_calibration_page

        open_set = None
        if open_set_runs > 0:
            open_set = evaluate_open_set(res["features"][r0], runs=open_set_runs, max_train=max_train,
                                         classifier=classifier, small_classes="drop", n_jobs=n_jobs,
                                         progress=progress, rng=seed)
        write_calibration_page(spatial, open_set, output, radius_m=r0,
                               command=f"Made by `orokit report --features {feature_set} --classifier {classifier} "
                                       f"--runs {runs} --open-set-runs {open_set_runs} --seed {seed}` (`make "
                                       f"classification` for the default model).")
    for r, e in sorted(res["evaluations"].items()):
        sp = e["spatial"].mean_accuracy
        sp_text = f"{100 * sp:.1f} %" if sp == sp else "not measurable (crops too small for this radius)"
        click.echo(f"R = {r / 1000:g} km: random split {100 * e['random'].mean_accuracy:.1f} %, spatial hold-out "
                   f"{sp_text}")
    click.echo(f"report -> {output}")
