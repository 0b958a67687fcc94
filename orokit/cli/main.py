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
    "generators-run": "orokit.cli.generators_cmd:generators_run",
    "generators-report": "orokit.cli.generators_cmd:generators_report",
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

    def invoke(self, ctx: click.Context):  # noqa: D102 - one-line errors, "interrupted" on Ctrl-C
        from orokit.errors import OrokitError

        verbose = bool(ctx.obj and ctx.obj.get("verbose", 0) >= 2)
        previous = _catch_sigterm()
        try:
            return super().invoke(ctx)
        except OrokitError as exc:
            if verbose:
                raise
            click.echo(f"Error: {exc}", err=True)
            sys.exit(1)
        except (KeyboardInterrupt, SystemError) as exc:
            # Ctrl-C inside a numba/C stage may surface as a SystemError whose context is the
            # KeyboardInterrupt; either way the outputs were left as they were (staged writes)
            if isinstance(exc, SystemError) and not _caused_by(exc, KeyboardInterrupt):
                raise
            if verbose:
                raise
            terminated = _caused_by(exc, _Terminated)
            click.echo("terminated" if terminated else "interrupted", err=True)
            sys.exit(143 if terminated else 130)
        except Exception as exc:
            from orokit.io.atomic import is_no_space_error, no_space_error

            if verbose or not is_no_space_error(exc):
                raise
            click.echo(f"Error: {no_space_error(_where(ctx, exc), exc)}", err=True)
            sys.exit(1)
        finally:
            _restore_sigterm(previous)


class _Terminated(KeyboardInterrupt):
    """SIGTERM (``kill``), raised like Ctrl-C so staged outputs are cleaned up the same way."""


def _on_sigterm(signum, frame):  # noqa: ANN001 - signal handler signature
    raise _Terminated()


def _catch_sigterm():
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return None
    return signal.signal(signal.SIGTERM, _on_sigterm)


def _restore_sigterm(previous) -> None:  # noqa: ANN001
    import signal

    if previous is not None:
        signal.signal(signal.SIGTERM, previous)


def _caused_by(exc: BaseException, kind: type[BaseException]) -> bool:
    e: BaseException | None = exc
    for _ in range(5):
        if e is None:
            return False
        if isinstance(e, kind):
            return True
        e = e.__cause__ or e.__context__
    return False


def _where(ctx: click.Context, exc: BaseException) -> str:
    """Where a full disk was hit: the first output of the command, else the file."""
    outputs = (ctx.obj or {}).get("outputs") or []
    if outputs:
        return str(outputs[0].resolve())
    name = getattr(exc, "filename", None)
    return str(name) if name else "the output disk"


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
