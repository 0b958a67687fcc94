"""``orokit report-dataset NAME -o DIR``: summary page + hillshade of one manifest DEM."""
from __future__ import annotations

from pathlib import Path

import click

from orokit.cli.options import overwrite_option, refuse_existing


@click.command("report-dataset")
@click.argument("name")
@click.option("-o", "--outdir", required=True, type=click.Path(file_okay=False), help="Output directory.")
@overwrite_option("an existing summary")
@click.pass_context
def report_dataset(ctx: click.Context, name: str, outdir: str, overwrite: bool) -> None:
    """Fetch the manifest DEM NAME, read it, and write DIR/summary.md, summary.json, hillshade.png."""
    from orokit.data import load_manifest, open_dataset_dem
    from orokit.reports.dem_summary import write_dem_summary

    out = Path(outdir)
    from orokit.cli.outputs import claim_outputs

    claim_outputs(out)  # locked for the whole run
    refuse_existing(out / "summary.md", overwrite=overwrite)
    manifest = load_manifest()
    ds = manifest[name]
    dem = open_dataset_dem(name, manifest=manifest)
    paths = write_dem_summary(dem, out, dataset=ds)
    if not (ctx.find_root().obj or {}).get("quiet"):
        click.echo(f"{name}: wrote {paths['md']}")
