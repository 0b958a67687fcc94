"""``orokit analysis-report``: table and Divide Tree figures of analysis folders."""
from __future__ import annotations

from pathlib import Path

import click

from orokit.cli.options import overwrite_option, refuse_existing


@click.command("analysis-report")
@click.argument("folders", nargs=-1, required=True, type=click.Path(file_okay=False, exists=True, path_type=Path))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="Markdown file to write (figures go to figures/ beside it).")
@overwrite_option("an existing report")
def analysis_report(folders: tuple[Path, ...], output: Path, overwrite: bool) -> None:
    """Summarise `orokit analyze` output FOLDERS: peaks, exactness, timings, agreement with the
    reference Divide Trees of the manifest, and a Divide Tree figure per dataset."""
    from orokit.reports.analysis_report import build_analysis_report

    from orokit.cli.outputs import claim_outputs

    claim_outputs(output)  # locked for the whole run
    refuse_existing(output, overwrite=overwrite)
    build_analysis_report(list(folders), output)
    click.echo(f"wrote {output}")
