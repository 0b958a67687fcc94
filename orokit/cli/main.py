"""The ``orokit`` click group.

Sub-commands are registered lazily by name -> "module:function", so ``orokit --help``
stays fast and each command lives in its own module under :mod:`orokit.cli`.
"""
from __future__ import annotations

import importlib
import logging
import sys

import click

from orokit import __version__

#: command name -> "module:attribute" of a click.Command
COMMANDS: dict[str, str] = {
    "data": "orokit.cli.data:data",
    "report-dataset": "orokit.cli.report_dataset:report_dataset",
    "report-index": "orokit.cli.report_index:report_index",
    "analyze": "orokit.cli.analyze:analyze",
    "analysis-report": "orokit.cli.analysis_report:analysis_report",
    "features": "orokit.cli.features:features",
    "train": "orokit.cli.train:train",
    "classify": "orokit.cli.classify:classify",
    "report": "orokit.cli.report:report",
    "type": "orokit.cli.type_cmd:type_cmd",
    "synthesize-tree": "orokit.cli.synthesize_tree:synthesize_tree",
    "synthesis-report": "orokit.cli.synthesis_report:synthesis_report",
    "render": "orokit.cli.render:render",
    "synthesize": "orokit.cli.synthesize:synthesize",
    "validate": "orokit.cli.validate:validate",
    "roundtrip-report": "orokit.cli.roundtrip_report:roundtrip_report",
}


class LazyGroup(click.Group):
    """A click group that imports each sub-command only when it is used."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(COMMANDS)

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        target = COMMANDS.get(name)
        if target is None:
            return None
        module, attr = target.split(":")
        return getattr(importlib.import_module(module), attr)

    def invoke(self, ctx: click.Context):  # noqa: D102 - one-line errors for OrokitError
        from orokit.errors import OrokitError

        try:
            return super().invoke(ctx)
        except OrokitError as exc:
            if ctx.obj and ctx.obj.get("verbose", 0) >= 2:
                raise
            click.echo(f"Error: {exc}", err=True)
            sys.exit(1)


@click.group(cls=LazyGroup)
@click.version_option(__version__, prog_name="orokit")
@click.option("-v", "--verbose", count=True, help="More log output (-vv shows tracebacks).")
@click.option("-q", "--quiet", is_flag=True, help="Only errors.")
@click.pass_context
def cli(ctx: click.Context, verbose: int, quiet: bool) -> None:
    """orokit: peaks, prominence, isolation, Divide Trees and orometric terrain synthesis."""
    ctx.ensure_object(dict)
    ctx.obj["verbose"] = verbose
    ctx.obj["quiet"] = quiet
    level = logging.ERROR if quiet else (logging.WARNING, logging.INFO, logging.DEBUG)[min(verbose, 2)]
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s")


if __name__ == "__main__":  # pragma: no cover
    cli()
