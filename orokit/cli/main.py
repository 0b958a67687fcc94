"""The ``orokit`` click group.

Sub-commands are registered lazily by name -> "module:function", so ``orokit --help``
stays fast and each command lives in its own module under :mod:`orokit.cli`.
``orokit --help`` lists the user commands first (in pipeline order), then the commands
that build the pages of ``reports/`` (:data:`REPORT_COMMANDS`).

Warnings (Python warnings and logged warnings) print as one line ``Warning: <message>``
on stderr; ``-v`` adds the logger name, ``-q`` hides them.
"""
from __future__ import annotations

import errno
import importlib
import logging
import sys
import warnings
from typing import NoReturn

import click

from orokit import __version__

#: user commands, in pipeline order: command name -> "module:attribute" of a click.Command
USER_COMMANDS: dict[str, str] = {
    "data": "orokit.cli.data:data",
    "analyze": "orokit.cli.analyze:analyze",
    "features": "orokit.cli.features:features",
    "train": "orokit.cli.train:train",
    "classify": "orokit.cli.classify:classify",
    "type": "orokit.cli.type_cmd:type_cmd",
    "synthesize-tree": "orokit.cli.synthesize_tree:synthesize_tree",
    "render": "orokit.cli.render:render",
    "synthesize": "orokit.cli.synthesize:synthesize",
    "validate": "orokit.cli.validate:validate",
    "compare": "orokit.cli.compare:compare",
}
#: commands that build the pages of reports/ (what `make report` runs)
REPORT_COMMANDS: dict[str, str] = {
    "report-dataset": "orokit.cli.report_dataset:report_dataset",
    "report-index": "orokit.cli.report_index:report_index",
    "analysis-report": "orokit.cli.analysis_report:analysis_report",
    "report": "orokit.cli.report:report",
    "synthesis-report": "orokit.cli.synthesis_report:synthesis_report",
    "roundtrip-report": "orokit.cli.roundtrip_report:roundtrip_report",
    "generators-run": "orokit.cli.generators_cmd:generators_run",
    "generators-report": "orokit.cli.generators_cmd:generators_report",
}
#: every command
COMMANDS: dict[str, str] = {**USER_COMMANDS, **REPORT_COMMANDS}

#: the short help of each command as `orokit --help` shows it, without importing the
#: command modules (which import numpy, rasterio...): checked against the commands by the tests
SHORT_HELP: dict[str, str] = {
    "data": "Real datasets of the manifest: list, fetch, verify, path.",
    "analyze": "Peaks, prominence, isolation and the Divide Tree of a DEM.",
    "features": "Orometric disk histograms of DEMs, analyses or peak lists.",
    "train": "Train and evaluate the region classifier.",
    "classify": "Classify a DEM, analysis or peak list with a trained model.",
    "type": "Terrain type (orometric statistics) of an analysis, DEM or tree.",
    "synthesize-tree": "Synthesize a Divide Tree following terrain type(s).",
    "render": "Render a Divide Tree to an elevation raster (COG).",
    "synthesize": "Synthesize a Divide Tree and its terrain in one go.",
    "validate": "Round trip of a rendered terrain: re-analysis, histograms, classes.",
    "compare": "Compare two peak lists (orokit, Kirmse, reference trees): matches, parents.",
    "report-dataset": "Summary page and hillshade of one manifest DEM.",
    "report-index": "Index page of the dataset summaries.",
    "analysis-report": "Table and Divide Tree figures of analysis folders.",
    "report": "Classification report (Table 2, confusion matrices, model).",
    "synthesis-report": "Fidelity table of synthesized trees.",
    "roundtrip-report": "Table and twin figures of the round trip.",
    "generators-run": "One generator on one tree: render, re-analysis, scores.",
    "generators-report": "Generator ranking table and side-by-side hillshades.",
}


class LazyGroup(click.Group):
    """A click group that imports each sub-command only when it is used.

    Called without arguments (the ``orokit`` console script, ``python -m orokit.cli.main``)
    it leaves the process without tearing the interpreter down (:func:`_leave`).
    """

    def __call__(self, *args, **kwargs):  # noqa: D102 - see the class docstring
        if args or kwargs:  # in-process use (tests, scripts): click's plain call
            return super().__call__(*args, **kwargs)
        main()

    def resolve_command(self, ctx: click.Context,  # noqa: D102 - the process's settings
                        args: list[str]) -> tuple[str | None, click.Command | None, list[str]]:
        if _CONSOLE["process"] and args and args[0] in COMMANDS:
            apply_process_settings(args[0])  # before the command's module imports numpy (and its BLAS threads)
        return super().resolve_command(ctx, args)

    def list_commands(self, ctx: click.Context) -> list[str]:
        return list(COMMANDS)

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        """Two sections: user commands (pipeline order), then report-building commands."""
        other = [name for name in COMMANDS if name not in USER_COMMANDS and name not in REPORT_COMMANDS]
        sections = [("Commands", list(USER_COMMANDS)), ("Report-building commands (make report)", list(REPORT_COMMANDS))]
        for title, names in sections + ([("Other commands", other)] if other else []):
            rows = []
            for name in names:
                text = SHORT_HELP.get(name)
                if text is None:  # a command without a SHORT_HELP entry: ask it (imports its module)
                    cmd = self.get_command(ctx, name)
                    text = cmd.get_short_help_str(formatter.width) if cmd is not None else ""
                rows.append((name, text))
            with formatter.section(title):
                formatter.write_dl(rows)

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        target = COMMANDS.get(name)
        if target is None:
            return None
        module, attr = target.split(":")
        return getattr(importlib.import_module(module), attr)

    def invoke(self, ctx: click.Context):  # noqa: D102 - one-line errors, "interrupted" on Ctrl-C
        from orokit.errors import OrokitError

        verbose = bool(ctx.obj and ctx.obj.get("verbose", 0) >= 2)
        previous = _catch_signals()
        try:
            result = super().invoke(ctx)
            _exit_if_stopped()  # a signal whose KeyboardInterrupt was swallowed on the way
            return result
        except OrokitError as exc:
            if verbose:
                raise
            click.echo(f"Error: {exc}{_option_hint(ctx, getattr(exc, 'path', None))}", err=True)
            sys.exit(1)
        except (KeyboardInterrupt, SystemError) as exc:
            # Ctrl-C inside a numba/C stage may surface as a SystemError whose context is the
            # KeyboardInterrupt; either way the outputs were left as they were (staged writes)
            if isinstance(exc, SystemError) and not _caused_by(exc, KeyboardInterrupt):
                raise
            if verbose:
                raise
            terminated = _caused_by(exc, _Terminated) or _stopped_by_sigterm()
            click.echo("terminated" if terminated else "interrupted", err=True)
            sys.exit(143 if terminated else 130)
        except Exception as exc:
            from orokit.io.atomic import is_no_space_error, no_space_error

            if not verbose and isinstance(exc, OSError) and _is_access_error(exc):
                name = exc.filename or _where(ctx, exc)
                verb = "write" if exc.errno == errno.EROFS else "access"
                click.echo(f"Error: cannot {verb} {name}: {str(exc.strerror).lower()}; the previous outputs were kept. "
                           f"Check its permissions, or write to a folder you can write to{_option_hint(ctx, name)}",
                           err=True)
                sys.exit(1)
            if verbose or not is_no_space_error(exc):
                raise
            click.echo(f"Error: {no_space_error(_where(ctx, exc), exc)}", err=True)
            sys.exit(1)
        finally:
            _restore_signals(previous)


#: set by :func:`main`: this process is the ``orokit`` program's own (not a caller's, e.g. a ``CliRunner`` test)
_CONSOLE = {"process": False}


def main() -> NoReturn:
    """The ``orokit`` console script (and ``python -m orokit.cli.main``): the command line, then the exit.

    Only here, where the process is orokit's own, do the commands get process-wide settings
    (:func:`apply_process_settings`); calling :data:`cli` with arguments or through click's
    ``CliRunner`` leaves the caller's process as it was. Never returns (:func:`_leave`).
    """
    _CONSOLE["process"] = True
    try:
        cli.main()  # standalone: ends with SystemExit
    except SystemExit as exc:
        _leave(exc)
    _leave(SystemExit(0))


def owns_process() -> bool:
    """True in the ``orokit`` program's process (:func:`main`), False when a caller runs a command in its own."""
    return _CONSOLE["process"]


#: ``orokit analyze``'s fixed malloc mmap threshold (:func:`orokit.tiling.memory.fix_mmap_threshold`)
MMAP_THRESHOLD_BYTES = 1 << 20
#: ... and a chunked run's, set when it starts: glibc's own ceiling. With 1 MB the chunked isolation
#: search's arrays of a few MB per batch were mapped, faulted in and zeroed again at every batch (session 16,
#: 1 G cells quiet, 256 chunks: 141.6 s wall, 224 CPU s, 849 MB against 100.2 s, 179 CPU s, 822 MB with
#: glibc's defaults)
CHUNKED_MMAP_THRESHOLD_BYTES = 32 << 20
#: ``orokit analyze``'s GIL switch interval until it writes its files (seconds), and while it writes
#: (Python's default: the writers' three threads held 1-3 MiB more at once at 0.5 ms, 15.1 M cells)
SWITCH_INTERVAL_S = 0.0005
WRITING_SWITCH_INTERVAL_S = 0.005


def apply_process_settings(command: str) -> None:
    """Process-wide settings for ``command``, applied by :func:`main` before the command runs.

    ``analyze``: at most two glibc malloc arenas (GDAL's reader, numba's loader and the
    writers' threads otherwise each keep an arena with its freed pages: ~10-20 MB of the
    peak at 15 M cells, measured in session 12), blocks of 1 MB or more always mapped on
    their own (freed arrays leave no resident pages in the heap), and Arrow's buffers from malloc, not
    mimalloc, whose segments stayed resident (~20 MB of the writing's peak), unless the
    user set ``ARROW_DEFAULT_MEMORY_POOL``; GDAL's block cache bounded to 32 MB unless the user
    set ``GDAL_CACHEMAX`` (:func:`orokit.tiling.memory.limit_gdal_cache`: a raster is read once; GDAL's
    default, 5 % of the RAM, kept +16-20 MB of a whole read of 15.1 M cells, and a chunked
    run's blocks for good); a GIL switch interval of :data:`SWITCH_INTERVAL_S` instead of 5 ms: a
    thread back from a call that released the GIL (numpy, GDAL, a kernel) waited up to the interval
    while a Python-bound thread (numba's loader, an import) held it, at each call (measured, session 16:
    the read's conversion of 60.5 M cells beside a Python thread 0.15-0.23 s of such waits per stripe
    thread against 0.03-0.09 at 0.5 ms; the finalize beside the tables' imports, median of 6, 0.21 s
    against 0.07); one OpenBLAS thread unless the user set ``OPENBLAS_NUM_THREADS`` (before numpy is
    imported: with two cores or more numpy's OpenBLAS starts a worker thread that spins 2^28 TSC cycles,
    ~0.1 s, beside the imports; analyze makes no BLAS call). Other commands run with the defaults (not
    measured).
    """
    if command != "analyze":
        return
    import os

    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

    from orokit.tiling.memory import fix_mmap_threshold, limit_gdal_cache, limit_malloc_arenas

    limit_malloc_arenas(2)
    fix_mmap_threshold(MMAP_THRESHOLD_BYTES)
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    os.environ.setdefault("ARROW_DEFAULT_MEMORY_POOL", "system")
    limit_gdal_cache()


def _leave(exc: SystemExit) -> NoReturn:
    """End the process with ``exc``'s status, skipping the interpreter's teardown when that is safe.

    Once numba has loaded a kernel, the teardown (module objects, LLVM) costs ~0.3 CPU s at
    every exit (measured: 0.25-0.4 s after the last output of ``orokit analyze``). Every file
    is complete and closed by then. The exit handlers (logging's flush, temporary folders)
    still run and both streams are flushed; with a non-daemon thread still alive, the
    normal exit (which waits for it) is taken instead.
    """
    import atexit
    import os
    import threading

    if any(t.is_alive() and not t.daemon for t in threading.enumerate() if t is not threading.main_thread()):
        raise exc
    code = exc.code
    if code is not None and not isinstance(code, int):  # sys.exit("message"): printed, status 1
        print(code, file=sys.stderr)
        code = 1
    atexit._run_exitfuncs()  # what a normal exit runs first (logging.shutdown, tempfile cleanup...)
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed or broken pipe: nothing more can be written
            pass
    os._exit(code or 0)


class _Terminated(KeyboardInterrupt):
    """SIGTERM (``kill``), raised like Ctrl-C so staged outputs are cleaned up the same way."""


#: how often a signal put off while the main thread starts or joins threads looks again
_JOIN_RETRY_S = 0.05
#: a signal put off (:func:`_on_signal`): its number, and whether the handler's next call is its return
_DEFERRED: dict[str, int | bool | None] = {"signum": None, "again": False}


def _joining(frame) -> bool:  # noqa: ANN001 - a frame object
    """Whether the main thread was interrupted while starting or joining a thread (``Thread.start`` waits
    for the thread to begin, ``Thread.join`` for it to end)."""
    import threading

    waits = {w.__code__ for w in (threading.Thread.start, threading.Thread.join,
                                  getattr(threading.Thread, "_wait_for_tstate_lock", threading.Thread.join))}
    while frame is not None and frame.f_code.co_filename == threading.__file__:
        if frame.f_code in waits:
            return True
        frame = frame.f_back
    return False


def _deliver_deferred() -> None:
    import signal
    import threading

    signum = _DEFERRED["signum"]
    if signum is not None:  # still catching (not restored since): the main thread's wait is woken, the handler runs
        _DEFERRED["again"] = True
        signal.pthread_kill(threading.main_thread().ident or 0, int(signum))


def _on_signal(signum, frame):  # noqa: ANN001 - signal handler signature
    """SIGINT / SIGTERM: recorded first (so no output is replaced after it, even if the exception
    below is swallowed somewhere), then raised as KeyboardInterrupt / :class:`_Terminated`.

    Not while the main thread starts or joins threads: the signal comes back every 50 ms until it is
    out (a second Ctrl-C raises at once). scipy's ``cKDTree.query(workers=-1)`` starts and joins threads
    that keep a bare pointer to the tree: raised there, the interrupt freed a temporary tree under them
    and Ctrl-C in ``orokit render`` crashed the process (segmentation fault, exit 139).
    """
    import signal
    import threading

    from orokit.io.atomic import request_stop

    request_stop(signum)
    again, _DEFERRED["again"] = bool(_DEFERRED["again"]), False
    first = _DEFERRED["signum"] is None
    if _joining(frame) and (first or again):
        if first:
            print("stopping once the running threads are done (Ctrl-C again: at once)", file=sys.stderr, flush=True)
        _DEFERRED["signum"] = signum
        timer = threading.Timer(_JOIN_RETRY_S, _deliver_deferred)
        timer.daemon = True
        timer.start()
        return
    _DEFERRED["signum"] = None
    raise _Terminated() if signum == signal.SIGTERM else KeyboardInterrupt()


def _catch_signals():
    import signal
    import threading

    from orokit.io.atomic import clear_stop

    clear_stop()
    if threading.current_thread() is not threading.main_thread():
        return None
    return {s: signal.signal(s, _on_signal) for s in (signal.SIGINT, signal.SIGTERM)}


def _restore_signals(previous) -> None:  # noqa: ANN001
    import signal

    _DEFERRED["signum"], _DEFERRED["again"] = None, False  # a signal put off is not sent again
    if previous is not None:
        for s, handler in previous.items():
            signal.signal(s, handler)


def _stopped_by_sigterm() -> bool:
    import signal

    from orokit.io.atomic import stop_requested

    return stop_requested() == signal.SIGTERM


def _exit_if_stopped() -> None:
    from orokit.io.atomic import stop_requested

    if stop_requested() is not None:
        raise _Terminated() if _stopped_by_sigterm() else KeyboardInterrupt()


def _caused_by(exc: BaseException, kind: type[BaseException]) -> bool:
    e: BaseException | None = exc
    for _ in range(5):
        if e is None:
            return False
        if isinstance(e, kind):
            return True
        e = e.__cause__ or e.__context__
    return False


def _option_hint(ctx: click.Context, path: object) -> str:
    """`` (--csv)``: the option that gave a refused output ``path``, or nothing."""
    from orokit.cli.outputs import option_for

    opt = option_for(ctx, path)
    return f" ({opt})" if opt else ""


def _is_access_error(exc: BaseException) -> bool:
    """An OSError of a file refused by the file system: read-only (EROFS) or not permitted (EACCES, EPERM)."""
    return isinstance(exc, OSError) and exc.errno in (errno.EROFS, errno.EACCES, errno.EPERM)


def _where(ctx: click.Context, exc: BaseException) -> str:
    """Where a full disk was hit: the first output of the command, else the file."""
    outputs = (ctx.obj or {}).get("outputs") or []
    if outputs:
        return str(outputs[0].resolve())
    name = getattr(exc, "filename", None)
    return str(name) if name else "the output disk"


class _OneLineFormatter(logging.Formatter):
    """``Warning: message`` / ``Error: message``; with -v also the logger name."""

    def __init__(self, verbose: int) -> None:
        super().__init__()
        self.verbose = verbose

    def format(self, record: logging.LogRecord) -> str:
        msg = record.getMessage()
        if record.exc_info and self.verbose >= 2:
            msg += "\n" + self.formatException(record.exc_info)
        if record.levelno >= logging.WARNING:
            head = "Error" if record.levelno >= logging.ERROR else "Warning"
            return f"{head}: {msg}" if not self.verbose else f"{head} ({record.name}): {msg}"
        return f"{record.levelname.lower()} {record.name}: {msg}"


def _format_warning(message, category, filename, lineno, line=None) -> str:  # noqa: ANN001
    """``warnings.formatwarning`` of the CLI: the message on one line, no source line.

    Only the formatting changes: filters and recorders (``pytest.warns``,
    ``catch_warnings(record=True)``) see every warning as before.
    """
    text = " ".join(str(message).split())
    from orokit.errors import OrokitWarning

    if not (category is UserWarning or issubclass(category, OrokitWarning)):
        text += f" ({category.__name__})"
    return f"Warning: {text}\n"


def _quiet_warning(message, category, filename, lineno, line=None) -> str:  # noqa: ANN001
    return ""


class _StderrHandler(logging.StreamHandler):
    """A stream handler that always writes to the current ``sys.stderr`` (click's test
    runner and pytest swap it between commands)."""

    @property
    def stream(self):  # noqa: D102
        return sys.stderr

    @stream.setter
    def stream(self, value) -> None:  # noqa: ANN001 - the stream is always sys.stderr
        pass


def setup_logging(verbose: int, quiet: bool) -> None:
    """Log level from -v/-q, one-line messages on stderr, Python warnings through the log.

    The handler filters by level (``-q``: errors only); ``-v``/``-vv`` lower the level of
    the ``orokit`` loggers to INFO/DEBUG (third-party libraries stay at WARNING).
    """
    level = logging.ERROR if quiet else (logging.WARNING, logging.INFO, logging.DEBUG)[min(verbose, 2)]
    handler = _StderrHandler()
    handler.setFormatter(_OneLineFormatter(verbose))
    handler.setLevel(level)
    handler._orokit_cli = True  # type: ignore[attr-defined]
    root = logging.getLogger()
    for h in list(root.handlers):
        if getattr(h, "_orokit_cli", False):
            root.removeHandler(h)
    root.addHandler(handler)
    if level < logging.WARNING:
        logging.getLogger("orokit").setLevel(level)
    warnings.formatwarning = _quiet_warning if quiet else _format_warning


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
    setup_logging(verbose, quiet)


if __name__ == "__main__":  # pragma: no cover
    # ``python -m orokit.cli.main`` runs this file as ``__main__``, a copy of the module the commands import:
    # the imported module's main(), so that its owns_process() (which they ask) is the one set
    from orokit.cli.main import main as _main

    _main()
