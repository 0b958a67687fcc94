"""``orokit report-index SUMMARY_JSON... -o INDEX.md``: index page of dataset summaries."""
from __future__ import annotations

from pathlib import Path

import click

from orokit.cli.options import overwrite_option, refuse_existing


@click.command("report-index")
@click.argument("summaries", nargs=-1, required=True, type=click.Path(dir_okay=False, exists=True))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="Markdown file to write.")
@overwrite_option("an existing index")
@click.pass_context
def report_index(ctx: click.Context, summaries: tuple[str, ...], output: str, overwrite: bool) -> None:
    """Write a markdown index linking the summary.json files SUMMARIES (made by report-dataset)."""
    from orokit.io.atomic import write_text_atomic
    from orokit.reports.dem_summary import render_index

    out = Path(output)
    from orokit.cli.outputs import claim_outputs

    claim_outputs(out)  # locked for the whole run
    refuse_existing(out, overwrite=overwrite)
    write_text_atomic(out, render_index(list(summaries), out))
    if not (ctx.find_root().obj or {}).get("quiet"):
        click.echo(f"wrote {out} ({len(summaries)} datasets)")
