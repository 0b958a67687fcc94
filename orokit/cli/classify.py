"""``orokit classify``: predict the region type of a DEM or peak list with a trained model."""
from __future__ import annotations

import json
from pathlib import Path

import click

from orokit.cli.options import INPUT, common_input_options, overwrite_option, progress_option, seed_option


@click.command()
@click.argument("model_path", metavar="MODEL", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.argument("source", metavar="INPUT", type=INPUT)
@common_input_options
@click.option("--min-peaks", type=int, default=None,
              help="Skip disks with fewer peaks (default: the model's training value).")
@click.option("--threshold", type=float, default=None,
              help="Answer 'unknown' when the best region's mean calibrated disk probability is below this "
                   "(default: the model's threshold, chosen on the spatial hold-out; 0 never answers unknown).")
@click.option("--disk-threshold", type=float, default=None,
              help="A disk's answer is 'unknown' when its top calibrated probability is below this (default: the "
                   "model's; 0 never).")
@click.option("--json", "as_json", is_flag=True, help="Print label, probabilities, votes and per-disk results as JSON.")
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Write per-disk predictions to this CSV.")
@click.option("--map", "map_path", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Write every disk as a polygon with its class probabilities to this GeoPackage (DEM's CRS), "
                   "and a PNG map over the hillshade beside it (same name, .png). DEM inputs only.")
@seed_option(what="the disk placement")
@overwrite_option("existing --output / --map files")
@progress_option()
def classify(model_path, source, z_units, cell_size_m, region, isolation, min_peaks, threshold, disk_threshold,
             as_json, output, map_path, seed, overwrite, progress):
    """Classify INPUT (DEM file or manifest DEM name, `orokit analyze` folder, or peak list) with MODEL.

    Features are computed with the model's radius, eps and feature set; each disk is
    predicted with calibrated probabilities and the terrain label maximises the disks'
    summed log-probability ('unknown' when the best region is not confident enough).
    """
    from orokit.classify.inputs import open_input_dem
    from orokit.classify.model import load_model
    from orokit.classify.predict import classify_input, disk_map
    from orokit.cli.outputs import claim_outputs
    from orokit.cli.progress import StageProgress
    from orokit.io.atomic import atomic_path

    outputs = [p for p in (output, map_path, map_path.with_suffix(".png") if map_path else None) if p is not None]
    claim_outputs(*outputs)  # locked for the whole run
    existing = [str(p) for p in outputs if p.exists()]
    if existing and not overwrite:
        raise click.UsageError(f"{', '.join(existing)} exist(s); pass --overwrite to replace")
    if map_path is not None and map_path.suffix.lower() != ".gpkg":
        raise click.BadParameter(f"{map_path} must end in .gpkg (GeoPackage)", param_hint="--map")
    stages = ["read", "features and prediction"] + (["write"] if output is not None or map_path is not None else [])
    with StageProgress("classify", stages, enabled=progress) as bar:
        model = load_model(model_path)
        source.dem_options(z_units, cell_size_m)  # a manifest DEM: refuses contradicting --z-units/--cell-size
        dem = open_input_dem(str(source), z_units=z_units, cell_size_m=cell_size_m) if region is None else None
        if map_path is not None and dem is None:
            raise click.UsageError("--map needs a DEM input (a raster file or a manifest DEM name)")
        bar.advance()
        pred = classify_input(model, str(source), z_units=z_units, cell_size_m=cell_size_m, region=region,
                              isolation=isolation, min_peaks=min_peaks, threshold=threshold,
                              disk_threshold=disk_threshold, dem=dem, rng=seed)
        bar.advance()
        if output is not None:
            with atomic_path(output) as tmp:
                pred.disks.to_csv(tmp, index=False)
        if map_path is not None:
            from orokit.io.model_io import write_disk_map
            from orokit.reports.classification_map import write_classification_map_png

            disks = disk_map(pred, crs=dem.rio.crs)
            write_disk_map(disks, map_path)
            write_classification_map_png(dem, disks, model.classes, map_path.with_suffix(".png"),
                                         title=f"{Path(str(source)).name}: {pred.label} "
                                               f"(R = {model.radius_m / 1000:g} km)")
        if output is not None or map_path is not None:
            bar.advance()
    if as_json:
        click.echo(json.dumps(pred.to_dict(), indent=2, default=float))
    else:
        top = sorted(pred.probabilities.items(), key=lambda kv: -kv[1])[:3]
        extra = f" (best: {pred.best})" if pred.label != pred.best else ""
        click.echo(f"{source}: {pred.label}{extra} ({len(pred.disks)} disks, {pred.unknown_disks} of them unknown; "
                   f"mean calibrated probability of the best region {100 * pred.confidence:.0f} %, 'unknown' below "
                   f"{100 * (pred.threshold or 0.0):.0f} %; terrain posterior "
                   + ", ".join(f"{k} {100 * v:.1f} %" for k, v in top) + ")")
