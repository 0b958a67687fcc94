"""Small input files read whole (type JSON, metadata), with errors that name the file and the fix."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from orokit._typing import PathLike
from orokit.errors import InputError

__all__ = ["read_input_bytes", "read_json_file"]


def read_input_bytes(path: PathLike, *, what: str, fix: str = "") -> bytes:
    """Bytes of the input file ``path`` (``what`` names it in errors: "terrain type file").

    Raises
    ------
    InputError
        The file does not exist, is a folder, or cannot be read (``fix`` is appended).
    """
    p = Path(path)
    try:
        return p.read_bytes()
    except FileNotFoundError:
        raise InputError(f"{what} {p} does not exist") from None
    except IsADirectoryError:
        raise InputError(f"{what} {p} is a folder{'; ' + fix if fix else ''}") from None
    except OSError as exc:
        raise InputError(f"cannot read {what} {p}: {exc.strerror or exc}") from None


def read_json_file(path: PathLike, *, what: str) -> Any:
    """Parsed JSON of ``path``.

    Raises
    ------
    InputError
        Missing, unreadable or not JSON.
    """
    raw = read_input_bytes(path, what=what)
    try:
        return json.loads(raw)
    except (json.JSONDecodeError, UnicodeDecodeError, RecursionError) as exc:
        raise InputError(f"{what} {path} is not valid JSON ({exc})") from None
