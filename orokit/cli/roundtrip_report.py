"""``orokit roundtrip-report``: table and twin figures of synthesized-and-validated regions."""
from __future__ import annotations

from pathlib import Path

import click

from orokit.cli.options import overwrite_option, progress_option


@click.command(name="roundtrip-report")
@click.argument("twins", nargs=-1, required=True, type=click.Path(exists=True, file_okay=False, path_type=Path))
@click.option("--classification", "per_class", type=click.Path(exists=True, dir_okay=False, path_type=Path),
              default=None, help="Per-region accuracy of real disks (classification report tables/per_class_*.csv).")
@click.option("--model", default="", help="Model name to quote in the report.")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="Markdown file to write (TWIN/twin.png figures and the table CSV are written first).")
@click.option("--table", "table_path", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="CSV of the table [default: OUTPUT with the suffix .csv, e.g. README.csv].")
@click.option("--renders", type=click.Path(exists=True, file_okay=False, path_type=Path), default=None,
              help="Folder of renders of the real Divide Trees, REGION.tif (`orokit render ... --like REGION`): "
                   "landforms compare real, render of the real tree and twin.")
@overwrite_option("existing outputs (OUTPUT, the table, TWIN/twin.png, TWIN/landforms.png)")
@progress_option()
def roundtrip_report(twins, per_class, model, output, table_path, renders, overwrite, progress) -> None:
    """Tabulate the round trip of TWINS (folders of `orokit synthesize --like` + `orokit validate`).

    Writes TWIN/twin.png and TWIN/landforms.png (real DEM, render of its real tree with
    --renders, twin: hillshades and slope / 1 km relief distributions) for every twin, the
    table as CSV (--table) and, last, OUTPUT with a landform table per region.
    """
    import logging

    import pandas as pd
    from tqdm.auto import tqdm

    from orokit.errors import InputError
    from orokit.io.atomic import write_text_atomic
    from orokit.io.dem import read_dem
    from orokit.reports.roundtrip import (
        landform_table,
        real_dem_of,
        render_roundtrip_markdown,
        roundtrip_rows,
        write_landform_png,
        write_twin_png,
    )

    table_path = table_path if table_path is not None else default_table_path(output)
    if table_path.resolve() == output.resolve():
        raise click.BadParameter(f"the table {table_path} would replace OUTPUT; give another --table",
                                 param_hint="--table")
    outputs = [output, table_path] + [d / "twin.png" for d in twins] + [d / "landforms.png" for d in twins]
    from orokit.cli.outputs import claim_outputs

    claim_outputs(*outputs)  # locked for the whole run
    existing = [str(p) for p in outputs if p.exists()]
    if existing and not overwrite:
        raise click.UsageError(f"{', '.join(existing)} exist(s); pass --overwrite to replace them")
    for d in twins:
        for f in ("validation.json", "dem.tif"):
            if not (d / f).is_file():
                raise click.BadParameter(f"{d} has no {f}; run `orokit synthesize -o {d}` and `orokit validate {d}`",
                                         param_hint="TWINS")
    real = pd.read_csv(per_class) if per_class is not None else None
    table = roundtrip_rows(list(twins), real_accuracy=real)
    landforms = {}
    for d in tqdm(twins, desc="twin figures and landforms", disable=not progress):
        real_dem, twin = real_dem_of(d), read_dem(str(d / "dem.tif"), z_units="m")
        write_twin_png(real_dem, twin, d / "twin.png", title=d.name)
        if real_dem is None:
            continue
        synthetic = {}
        if renders is not None and (renders / f"{d.name}.tif").is_file():
            synthetic["render of its real tree"] = read_dem(str(renders / f"{d.name}.tif"), z_units="m")
        synthetic["free twin"] = twin
        try:
            landforms[d.name] = landform_table(real_dem, synthetic)
        except InputError as exc:  # e.g. a twin at another cell size than its real DEM
            logging.getLogger(__name__).warning("%s: no landform table (%s)", d.name, exc)
            continue
        write_landform_png({"real DEM": real_dem, **synthetic}, d / "landforms.png", title=d.name)
    import json

    controls = {json.loads((d / "synthesis.json").read_text()).get("control_elevation")
                for d in twins if (d / "synthesis.json").is_file()}
    how = ("`orokit synthesize --like REGION --control-elevation like --seed 0`, erosion on: the real DEM's "
           "elevation is the coarse elevation control C_H of the paper's section 5, so the large-scale relief "
           "follows the real one while every peak, saddle, ridge, river and all detail are synthesized"
           if controls == {"like"} else "`orokit synthesize --like REGION --seed 0`, erosion on")
    header = ("Each region's terrain type (`orokit type` on its analysis) is synthesized on a domain of the real "
              f"DEM's size and cell size ({how}), re-analysed at "
              "eps = 30 m and classified by the region model (`orokit validate --model`). A tree peak >= eps is "
              "recovered when a raster peak lies within max(2 cells, 100 m) with a prominence within "
              "max(15 m, 10 %); extra = raster peaks >= eps with no tree peak within that distance. Histogram "
              "errors compare the re-analysed raster's Divide Tree with the type. Real-disk accuracy is the "
              "classification report's per-region accuracy of the same region's real disks.")
    if per_class is not None:
        header += f" Real accuracies from `{per_class}`."
    # render times change with the machine's load: to the git-ignored timings.csv, not the committed table
    if "render_s" in table:
        write_text_atomic(output.parent / "timings.csv", table[["region", "render_s"]].to_csv(index=False))
        table = table.drop(columns="render_s")
    write_text_atomic(table_path, table.to_csv(index=False))
    write_text_atomic(output, render_roundtrip_markdown(table, header=header, model=model, landforms=landforms))
    click.echo(f"{len(table)} twins -> {output}, {table_path}")


def default_table_path(output: Path) -> Path:
    """CSV beside the markdown OUTPUT, named after it (``README.md`` -> ``README.csv``).

    Distinct from the append log of ``orokit validate --append-to`` and never OUTPUT itself.
    """
    output = Path(output)
    if output.suffix.lower() == ".csv":
        return output.with_name(output.stem + ".table.csv")
    return output.with_suffix(".csv")
