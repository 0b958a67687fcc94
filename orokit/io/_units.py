"""Elevation units: names accepted by orokit and their factor to metres."""
from __future__ import annotations

from orokit.errors import UnitsError

#: canonical unit -> metres per unit (international foot: exactly 0.3048 m)
TO_METRES: dict[str, float] = {"m": 1.0, "ft": 0.3048, "us-ft": 1200.0 / 3937.0}

_ALIASES: dict[str, str] = {
    "m": "m", "metre": "m", "metres": "m", "meter": "m", "meters": "m",
    "ft": "ft", "foot": "ft", "feet": "ft", "international foot": "ft", "international feet": "ft",
    "us-ft": "us-ft", "us_ft": "us-ft", "ftus": "us-ft", "us survey foot": "us-ft", "us survey feet": "us-ft",
}


def normalize_units(units: str, *, what: str = "elevation units") -> str:
    """Return the canonical name (``"m"``, ``"ft"``, ``"us-ft"``) of a units string.

    Raises
    ------
    UnitsError
        If ``units`` is not a known name; the message lists the accepted ones.
    """
    key = str(units).strip().lower()
    if key in _ALIASES:
        return _ALIASES[key]
    raise UnitsError(
        f"unknown {what} {units!r}; accepted: 'm' (metre, meters...), 'ft' (foot, feet: x 0.3048) "
        f"or 'us-ft' (US survey foot). Pass e.g. z_units='ft' (CLI: --z-units ft)."
    )


def is_known_units(units: str | None) -> bool:
    """True when ``units`` is a recognised unit name."""
    return units is not None and str(units).strip().lower() in _ALIASES


def factor_to_metres(units: str) -> float:
    """Metres per unit for a units string (see :func:`normalize_units`)."""
    return TO_METRES[normalize_units(units)]
