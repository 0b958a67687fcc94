"""``orokit validate``: round trip of a rendered terrain (re-analysis, histograms, classification)."""
from __future__ import annotations

import datetime as _dt
from pathlib import Path

import click

from orokit.cli.options import (
    LENGTH,
    min_prominence_option,
    overwrite_option,
    progress_option,
    refuse_existing,
    seed_option,
    z_units_option,
)


def append_row(table: Path, row: dict) -> None:
    """Append one row to a CSV table (rewritten atomically; new columns are added)."""
    import pandas as pd

    from orokit.io.atomic import atomic_path, output_lock

    df = pd.DataFrame([row])
    with output_lock(table, wait_s=60.0):  # concurrent runs append one after the other
        if table.exists():
            old = pd.read_csv(table).rename(columns={"min_prominence": "min_prominence_m"})  # logs of older versions
            df = pd.concat([old, df], ignore_index=True)
        table.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(table) as tmp:
            df.to_csv(tmp, index=False)


@click.command(name="validate")
@click.argument("out", type=click.Path(exists=True, path_type=Path))
@click.option("--model", "model_path", type=click.Path(exists=True, dir_okay=False, path_type=Path), default=None,
              help="Trained region model (.skops) to classify the terrain with.")
@click.option("--tree", "tree_path", type=click.Path(exists=True, path_type=Path), default=None,
              help="Divide Tree the raster was rendered from (default: OUT/dividetree.gpkg).")
@click.option("--type", "type_file", type=click.Path(exists=True, dir_okay=False, path_type=Path), default=None,
              help="Terrain type JSON to compare histograms with (default: the one in OUT/synthesis.json).")
@click.option("--label", default=None, help="Expected region (default: the type's name).")
@min_prominence_option(help="Prominence threshold eps of the re-analysis")
@z_units_option(help="Elevation units of a raster that declares none (rasters of `orokit render`/`synthesize` "
                   "declare metres).")
@click.option("-o", "--output", "json_path", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Validation JSON to write [default: OUT/validation.json when OUT is a folder; none for a "
                   "raster, whose summary is only printed].")
@click.option("--append-to", "append_to", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="CSV log to append the run's summary row to (created if missing). Default: no log.")
@overwrite_option("an existing validation JSON")
@seed_option(what="the disk placement")
@click.option("--real", "real", default=None,
              help="Real DEM (file or manifest dataset) to compare landforms with [default: the --like DEM of "
                   "OUT/synthesis.json, if any].")
@click.option("--real-cell-size", type=LENGTH, default=None,
              help="Cell size of a --real file without georeference (a length: 92.6m; a plain number is metres).")
@progress_option()
def validate(out, model_path, tree_path, type_file, label, min_prominence_m, z_units, json_path, append_to, overwrite,
             seed, real, real_cell_size, progress) -> None:
    """Re-analyse OUT (a synthesize folder or a raster), compare it with its Divide Tree, classify it.

    Writes OUT/validation.json for a folder (or -o JSON) and, with --append-to, one row to a CSV log;
    nothing else.
    """
    import json

    folder = out if out.is_dir() else None
    raster = folder / "dem.tif" if folder else out
    if json_path is None and folder is not None:
        json_path = folder / "validation.json"
    from orokit.cli.outputs import claim_outputs

    claim_outputs(json_path)  # locked for the whole run (the --append-to log only while appending)
    refuse_existing(json_path, overwrite=overwrite)
    if append_to is not None and append_to.exists() and append_to.is_dir():
        raise click.BadParameter(f"{append_to} is a folder; give the CSV file to append to", param_hint="--append-to")
    if folder is not None and not raster.is_file():
        if (folder / "analysis.json").exists():
            raise click.UsageError(
                f"{folder} is an `orokit analyze` folder (no dem.tif): validate a raster rendered from its tree, "
                f"e.g. `orokit render {folder / 'dividetree.gpkg'} -o DEM.tif` then "
                f"`orokit validate DEM.tif --tree {folder / 'dividetree.gpkg'}`")
        raise click.UsageError(f"{folder} has no dem.tif; run `orokit synthesize -o {folder}` (or give the raster)")
    if tree_path is None:
        if folder is None or not (folder / "dividetree.gpkg").exists():
            raise click.UsageError("give --tree (the Divide Tree the raster was rendered from)")
        tree_path = folder / "dividetree.gpkg"
    if folder is not None and (folder / "synthesis.json").exists():
        meta = json.loads((folder / "synthesis.json").read_text())
        types = meta.get("types") or []
        if type_file is None and len(types) == 1 and Path(types[0]).exists():
            type_file = Path(types[0])
        if real is None and meta.get("like"):
            real = meta["like"]

    from orokit.cli.progress import StageProgress
    from orokit.cli.render import read_tree
    from orokit.io.atomic import write_text_atomic
    from orokit.io.dem import read_dem
    from orokit.validate.roundtrip import roundtrip, summary_json

    stages = ["read", "re-analyse and compare"] + (["landforms vs real"] if real is not None else []) + ["write"]
    with StageProgress("validate", stages, enabled=progress) as bar:
        dem = read_dem(str(raster), z_units=z_units)
        tree = read_tree(tree_path)
        ttype = None
        if type_file is not None:
            from orokit.synthesis.terrain_type import load_terrain_type

            ttype = load_terrain_type(type_file)
        model = None
        if model_path is not None:
            from orokit.classify.model import load_model

            model = load_model(model_path)
        bar.advance()
        rt = roundtrip(dem, tree, min_prominence_m=min_prominence_m, terrain_type=ttype, model=model,
                       expected_label=label, rng=seed)
        s = rt.summary()
        bar.advance()
        landform = None
        if real is not None:
            from orokit.cli.render import like_dem
            from orokit.validate.landform import compare_landforms

            landform = compare_landforms(like_dem(real, cell_size_m=real_cell_size, z_units=None, hint="--real"), dem)
            bar.advance()
        if json_path is not None:
            doc = json.loads(summary_json(rt))
            if landform is not None:
                doc["landform"] = {"real": str(real), "table": landform.reset_index().to_dict(orient="records")}
            write_text_atomic(json_path, json.dumps(doc, indent=2))
        if append_to is not None:
            row = {"time": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"), "raster": str(raster),
                   "tree": str(tree_path), "model": str(model_path) if model_path else "", **s}
            append_row(append_to, row)
        bar.advance()
    msg = (f"recovered {100 * s['recovered_share']:.1f} % of {s['tree_peaks']} tree peaks >= {min_prominence_m:g} m, "
           f"{s['extra_peaks']} extra ({100 * s['extra_share']:.1f} %)")
    if "max_bin_error" in s:
        msg += f"; max histogram bin error {s['max_bin_error']:.3f}"
    if model is not None:
        if not s.get("n_disks"):
            msg += f"; not classified: no disk of radius {model.radius_m / 1000:g} km fits"
        else:
            msg += f"; classified as {s['predicted']}"
            if "disk_accuracy" in s:
                msg += f" ({100 * s['disk_accuracy']:.0f} % of {s['n_disks']} disks right)"
    written = [str(p) for p in (json_path, append_to) if p is not None]
    click.echo(msg + (f" -> {', '.join(written)}" if written else ""))
    if landform is not None:
        click.echo(f"landforms vs {real} (distance; real north/south halves; target = max(2 x halves, floor)):")
        for name, row in landform.iterrows():
            click.echo(f"  {name:17s} {row['distance']:9.4g}  halves {row['halves']:9.4g}  target {row['target']:9.4g}"
                       f"  {'ok' if row['ok'] else 'OVER'}")
