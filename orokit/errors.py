"""Exception and warning classes of orokit.

Every error raised at a public boundary is an :class:`OrokitError`, so the CLI can
print it as one line and exit with code 1.
"""
from __future__ import annotations


class OrokitError(Exception):
    """Base class of all orokit errors."""


class InputError(OrokitError, ValueError):
    """An input file or array cannot be used (unreadable, empty, wrong shape...)."""


class CRSError(OrokitError, ValueError):
    """Missing or unusable coordinate reference system."""


class UnitsError(OrokitError, ValueError):
    """Unknown or inconsistent units (elevation or distance)."""


class TilingError(OrokitError):
    """Chunked / tiled computation failed."""


class DivideTreeError(OrokitError, ValueError):
    """A Divide Tree is malformed (cycle, saddle above a peak, bad ids...)."""


class SchemaError(OrokitError, ValueError):
    """A table, model or type file does not have the expected columns/version."""


class OutputError(OrokitError):
    """An output cannot be written: another orokit process is writing it, or no space is left.

    ``path``: the refused output, when known (the CLI names the option that gave it).
    """

    def __init__(self, message: str, *, path: object = None) -> None:
        super().__init__(message)
        self.path = path


class DataError(OrokitError):
    """Dataset manifest, download or checksum problem."""


class OrokitWarning(UserWarning):
    """Warning category of orokit."""
