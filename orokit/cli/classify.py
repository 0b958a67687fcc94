"""``orokit classify``: predict the region type of a DEM or peak list with a trained model."""
from __future__ import annotations

import json
from pathlib import Path

import click

from orokit.cli.options import common_input_options


@click.command()
@click.argument("model_path", metavar="MODEL", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.argument("source", metavar="INPUT", type=click.Path(exists=True, path_type=Path))
@common_input_options
@click.option("--min-peaks", type=int, default=None,
              help="Skip disks with fewer peaks (default: the model's training value).")
@click.option("--json", "as_json", is_flag=True, help="Print label, probabilities, votes and per-disk results as JSON.")
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Write per-disk predictions to this CSV.")
@click.option("--seed", type=int, default=0, show_default=True, help="Seed of the disk placement.")
@click.option("--overwrite", is_flag=True, help="Replace an existing --output.")
def classify(model_path, source, z_units, cell_size, region, isolation, min_peaks, as_json, output, seed, overwrite):
    """Classify INPUT (DEM, `orokit analyze` folder or peak list) with MODEL (from `orokit train`).

    Features are computed with the model's radius, eps and bins; each disk is
    predicted and the overall label is the class with the highest mean probability.
    """
    from orokit.classify.model import load_model
    from orokit.classify.predict import classify_input
    from orokit.io.atomic import atomic_path

    from orokit.cli.outputs import claim_outputs

    claim_outputs(output)  # locked for the whole run
    if output is not None and output.exists() and not overwrite:
        raise click.UsageError(f"{output} exists; pass --overwrite to replace it")
    model = load_model(model_path)
    pred = classify_input(model, source, z_units=z_units, cell_size=cell_size, region=region, isolation=isolation,
                          min_peaks=min_peaks, rng=seed)
    if output is not None:
        with atomic_path(output) as tmp:
            pred.disks.to_csv(tmp, index=False)
    if as_json:
        d = pred.to_dict()
        if not output:
            d["disks"] = d["disks"]
        click.echo(json.dumps(d, indent=2, default=float))
    else:
        top = sorted(pred.probabilities.items(), key=lambda kv: -kv[1])[:5]
        click.echo(f"{source}: {pred.label} ({len(pred.disks)} disks; "
                   + ", ".join(f"{k} {100 * v:.1f} %" for k, v in top) + ")")
