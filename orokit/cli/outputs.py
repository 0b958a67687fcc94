"""What every writing command does with its outputs, for the whole run.

:func:`claim_outputs` is called at the start of a command, before it checks whether its
outputs exist: it takes the lock of each output until the command ends (a second
``orokit`` writing the same output fails at once), removes the hidden temporary files an
interrupted run left for them, and returns a :class:`~orokit.io.atomic.Staging` through
which new files are written and that the command commits at its very end. If the command
fails (an error, disk full, Ctrl-C), whatever was staged is removed and the previous
outputs stay as they were.
"""
from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path

import click

from orokit.io.atomic import Staging, output_lock, remove_stale_temps

__all__ = ["claim_outputs", "claimed_outputs", "option_for"]


@contextlib.contextmanager
def _claimed(paths: list[Path], names: tuple[str, ...] | None, stage: Staging) -> Iterator[Staging]:
    with output_lock(*paths):
        for p in paths:
            _check_writable(p)
            remove_stale_temps(p, names=names)
        try:
            yield stage
        finally:
            if not stage.committed:
                stage.abort()


def _check_writable(path: Path) -> None:
    """Refuse an output folder that exists but cannot be written into (a read-only mount, no permission): its
    lock lies beside it, so without this the command ran to its end and failed there."""
    import errno
    import os

    if path.is_dir() and not os.access(path, os.W_OK | os.X_OK):
        from orokit.errors import OutputError

        why = os.strerror(errno.EROFS if _read_only(path) else errno.EACCES).lower()
        raise OutputError(f"cannot write into {path}: {why}; write to a folder you can write to", path=path)


def _read_only(path: Path) -> bool:
    """True when ``path`` lies on a file system mounted read-only."""
    import os

    try:
        return bool(os.statvfs(path).f_flag & os.ST_RDONLY)
    except OSError:
        return False


def claim_outputs(*paths: Path | str | None, names: tuple[str, ...] | None = None) -> Staging:
    """Lock ``paths`` (files or folders; ``None`` skipped) until the current command ends.

    ``names``: for folder outputs, the file names the command writes inside them (stale
    temporary files of only those are removed); ``None`` removes every stale one.
    Raises :class:`~orokit.errors.OutputError` when another process writes one of them.
    """
    ctx = click.get_current_context()
    chosen = [Path(p) for p in paths if p is not None]
    root = ctx.find_root()
    if isinstance(root.obj, dict):
        root.obj.setdefault("outputs", []).extend(chosen)
        root.obj.setdefault("path_options", []).extend(_path_options(ctx))
    return ctx.with_resource(_claimed(chosen, names, Staging()))


def _path_options(ctx: click.Context) -> list[tuple[Path, str]]:
    """The command's path-valued parameters: (path, how the user names it: ``-o/--output``, ``--csv``, ``OUT``)."""
    found = []
    for param in ctx.command.params:
        value = ctx.params.get(param.name or "")
        values = value if isinstance(value, (list, tuple)) else [value]
        name = "/".join(param.opts) if isinstance(param, click.Option) else param.human_readable_name
        found += [(Path(v), name) for v in values if isinstance(v, Path)]
    return found


def option_for(ctx: click.Context, path: object) -> str | None:
    """The option of the command run under ``ctx`` that gave ``path`` (it or a folder holding it), e.g.
    ``--csv``; None when none did."""
    import os

    if path is None or not isinstance(ctx.find_root().obj, dict):
        return None
    target = Path(os.path.abspath(str(path)))
    best: tuple[int, str] | None = None
    for p, name in ctx.find_root().obj.get("path_options", []):
        a = Path(os.path.abspath(p))
        if (target == a or a in target.parents) and (best is None or len(a.parts) > best[0]):
            best = (len(a.parts), name)
    return None if best is None else best[1]


def claimed_outputs() -> list[Path]:
    """The outputs claimed by the running command (for error messages)."""
    ctx = click.get_current_context(silent=True)
    if ctx is None or not isinstance(ctx.find_root().obj, dict):
        return []
    return list(ctx.find_root().obj.get("outputs", []))
