"""``orokit features``: orometric disk histograms of DEMs, analysis folders or peak lists."""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import click

if TYPE_CHECKING:  # pragma: no cover
    import pandas as pd

from orokit.cli.options import (
    INPUT,
    RADIUS,
    common_input_options,
    min_prominence_option,
    overwrite_option,
    progress_option,
    seed_option,
)


@click.command()
@click.argument("inputs", nargs=-1, required=True, type=INPUT)
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="Feature table to write (Parquet, one row per disk).")
@click.option("--radius", type=RADIUS, default="10km", show_default=True,
              help="Disk radius R on the ground, with unit (10km, 5000m; a bare number is metres).")
@min_prominence_option()
@click.option("--min-peaks", type=int, default=20, show_default=True,
              help="Skip (and count) disks with fewer peaks than this.")
@click.option("--max-disks", type=int, default=100, show_default=True, help="At most this many disks per input.")
@click.option("--separation", type=float, default=0.5, show_default=True,
              help="Minimum disk-centre distance as a fraction of R.")
@click.option("--label", "labels", multiple=True,
              help="Region label: once for all inputs, or once per input (default: dataset / file name).")
@click.option("--features", "feature_set_name", type=click.Choice(["auto", "orometry", "terrain", "paper"]),
              default="auto", show_default=True,
              help="Feature set: terrain (orometry plus slope, relief, curvature, hypsometry, spectral slope and "
                   "drainage of the DEM in each disk; inputs with a DEM only), orometry (histograms and disk "
                   "summaries of the peaks at R; works on peak lists), auto (terrain when every input has a DEM, "
                   "else orometry; both chosen on the spatial hold-out) or paper (Argudo et al. 2019, Table 1, the "
                   "reference mode).")
@click.option("--relative-elevation", type=click.Choice(["minmax", "max"]), default="minmax", show_default=True,
              help="Relative elevation (h-min)/(max-min) over the disk, or h/max.")
@click.option("--exact-only", is_flag=True, help="Drop peaks whose prominence is flagged not exact (edge effects).")
@common_input_options
@seed_option(what="the disk placement")
@overwrite_option("an existing OUTPUT")
@click.option("--n-jobs", type=click.IntRange(min=1), default=2, show_default=True,
              help="Inputs measured at once, each in its own process (the table does not depend on it).")
@progress_option()
def features(inputs, output, radius, min_prominence_m, min_peaks, max_disks, separation, labels, feature_set_name,
             relative_elevation, exact_only, z_units, cell_size_m, region, isolation, seed, overwrite, n_jobs, progress):
    """Orometric histograms of disks of radius R placed by blue noise in each INPUT.

    INPUT is a DEM file or the name of a DEM of the datasets manifest (analysed on the
    fly; disks entirely inside its valid cells), an
    `orokit analyze` output folder, or a peak list (orokit table or Kirmse & de
    Ferranti prominence list; with --region, disks inside the polygon eroded by R).
    Distances are measured on the ground (geodesic for lon/lat data). Histogram
    columns are named <feature>_<bin>.
    """
    import numpy as np

    from orokit.classify.features import concat_features
    from orokit.io.model_io import write_feature_table
    from orokit.classify.inputs import auto_feature_set, features_for_input
    from orokit.sampling.feature_sets import FeatureSet

    from orokit.cli.outputs import claim_outputs

    claim_outputs(output)  # locked for the whole run
    if output.exists() and not overwrite:
        raise click.UsageError(f"{output} exists; pass --overwrite to replace it")
    if labels and len(labels) not in (1, len(inputs)):
        raise click.BadParameter(f"give --label once or once per input ({len(inputs)}), got {len(labels)}",
                                 param_hint="--label")
    seeds = np.random.SeedSequence(seed).spawn(len(inputs))
    fs = auto_feature_set([str(s) for s in inputs]) if feature_set_name == "auto" else FeatureSet.named(feature_set_name)
    jobs = []
    for i, src in enumerate(inputs):
        label = (labels[i] if len(labels) == len(inputs) else labels[0]) if labels else src.label
        z, cell = src.dem_options(z_units, cell_size_m)
        jobs.append(dict(
            source=str(src), radius_m=radius, label=label, min_prominence_m=min_prominence_m, min_peaks=min_peaks,
            max_disks=max_disks, separation=separation, relative_elevation=relative_elevation,
            feature_set=fs,
            exact_only=exact_only, z_units=z, cell_size_m=cell, region=region, isolation=isolation,
            rng=np.random.default_rng(seeds[i])))
    bar = None
    if progress and len(inputs) > 1:
        from tqdm.auto import tqdm

        bar = tqdm(total=len(jobs), desc="features", unit="input")
    workers = min(n_jobs, len(jobs))
    if workers <= 1:
        tables = []
        for job in jobs:
            tables.append(features_for_input(**job))
            if bar is not None:
                bar.update()
    else:  # one process per input at a time: each input's disks come from its own seed, so the order does not matter
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        method = "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"
        with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context(method)) as pool:
            futures = [pool.submit(_features_job, job) for job in jobs]
            tables = []
            for fut in futures:
                tables.append(fut.result())
                if bar is not None:
                    bar.update()
    if bar is not None:
        bar.close()
    table = concat_features(tables)
    write_feature_table(table, output)
    counts = table["label"].value_counts().to_dict() if len(table) else {}
    click.echo(f"features {fs.name!r}: {len(table)} disks of radius {radius / 1000:g} km ({table.attrs.get('n_disks_skipped', 0)} skipped "
               f"with < {min_peaks} peaks) from {len(inputs)} input(s) -> {output}; per label: {counts}")


def _features_job(job: dict) -> "pd.DataFrame":
    """One input's feature table, in a worker process."""
    from orokit.classify.inputs import features_for_input

    return features_for_input(**job)
