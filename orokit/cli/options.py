"""Options and parameter types shared by the orokit commands.

:class:`Length` is the one parser of lengths on the command line: ``90km``, ``500m``,
``30 m``, ``1.5km``, ``2e3m`` and, where a command documents it, a plain number of
metres. Sizes ``WxH`` (``90x60km``, ``9000 x 6000 m``) share one unit. Anything else
(``1.2.3km``, ``.``, ``-5km``, ``0m``, ``nan``, ``inf``) is refused with a message
naming the option.
"""
from __future__ import annotations

import math
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

__all__ = ["Length", "parse_length", "common_input_options"]

#: a non-negative decimal number: digits with an optional fraction, or a bare fraction,
#: optionally followed by an exponent; no sign, no second dot
_NUMBER = r"(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?"
_UNIT = r"(km|m)"
_LENGTH = re.compile(rf"^\s*({_NUMBER})\s*{_UNIT}?\s*$", re.IGNORECASE)
_SIZE = re.compile(rf"^\s*({_NUMBER})\s*(?:[xX]\s*({_NUMBER}))?\s*{_UNIT}?\s*$", re.IGNORECASE)
_FACTOR = {"m": 1.0, "km": 1000.0}


def parse_length(text: str | float, *, allow_bare: bool = True, bare_min_m: float | None = None,
                 pair: bool = False, hint: str | None = None) -> Any:
    """Parse a length (or a ``WxH`` size with ``pair=True``) into metres.

    Parameters
    ----------
    text : str or number
        ``"90km"``, ``"500m"``, ``"30 m"``; with ``allow_bare`` also ``"2500"`` (metres).
        A number (int/float) is taken as metres when ``allow_bare``.
    allow_bare : bool
        Accept numbers without a unit (metres).
    bare_min_m : float, optional
        Refuse a unit-less value below this (catches ``--radius 10`` meant as km).
    pair : bool
        Accept ``WxH`` and return ``(width, height)``; a single length gives a square.
    hint : str, optional
        Option name for the error message.

    Returns
    -------
    float or (float, float)
        Metres, always > 0 and finite.

    Raises
    ------
    click.BadParameter
        Anything that is not such a length, or a length <= 0.

    Examples
    --------
    >>> parse_length("90km"), parse_length("30 m"), parse_length("90x60km", pair=True)
    (90000.0, 30.0, (90000.0, 60000.0))
    """
    example = "90x60km, 90km or 90000m" if pair else "10km or 500m"
    if isinstance(text, (int, float)) and not isinstance(text, bool):
        if not allow_bare:
            raise click.BadParameter(f"{text!r} has no unit; write e.g. {example}", param_hint=hint)
        values, unit = [float(text)], None
    else:
        m = (_SIZE if pair else _LENGTH).match(str(text))
        if not m:
            noun = "size" if pair else "length"
            raise click.BadParameter(f"{text!r} is not a {noun}; write e.g. {example}", param_hint=hint)
        groups = m.groups()
        values = [float(g) for g in groups[:-1] if g is not None]
        unit = groups[-1].lower() if groups[-1] else None
    if unit is None:
        if not allow_bare:
            raise click.BadParameter(f"{text!r} has no unit; write e.g. {example}", param_hint=hint)
        if bare_min_m is not None and min(values) < bare_min_m:
            raise click.BadParameter(f"{text!r} without unit means {min(values):g} metres; did you mean {text}km?",
                                     param_hint=hint)
    metres = [v * _FACTOR[unit or "m"] for v in values]
    if not all(math.isfinite(v) and v > 0 for v in metres):
        raise click.BadParameter(f"length must be a positive finite number, got {text!r}", param_hint=hint)
    if pair:
        return (metres[0], metres[1] if len(metres) > 1 else metres[0])
    return metres[0]


class Length(click.ParamType):
    """Click type of a length in metres (``90km``, ``500m``; see :func:`parse_length`).

    Parameters
    ----------
    allow_bare : bool
        Plain numbers are metres (the command's help should say so).
    bare_min_m : float, optional
        Refuse unit-less values below this many metres.
    pair : bool
        Accept ``WxH`` sizes; the value is then ``(width_m, height_m)``.
    """

    def __init__(self, *, allow_bare: bool = True, bare_min_m: float | None = None, pair: bool = False) -> None:
        self.allow_bare = allow_bare
        self.bare_min_m = bare_min_m
        self.pair = pair
        self.name = "SIZE" if pair else "LENGTH"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:  # noqa: D102
        if self.pair and isinstance(value, tuple):
            return value
        try:
            return parse_length(value, allow_bare=self.allow_bare, bare_min_m=self.bare_min_m, pair=self.pair,
                                hint=None)
        except click.BadParameter as exc:
            self.fail(exc.message, param, ctx)


def common_input_options(f: Callable[..., Any]) -> Callable[..., Any]:
    """Options shared by ``features`` and ``classify`` to read an input."""
    for opt in reversed([
        click.option("--z-units", type=click.Choice(["m", "ft"]), default=None,
                     help="Elevation units of DEMs without units (PNG) and of Kirmse peak lists (default ft)."),
        click.option("--cell-size", type=float, default=None,
                     help="Cell size in METRES of DEMs without georeference (PNG): local metric grid."),
        click.option("--region", "region", type=click.Path(exists=True, dir_okay=False, path_type=Path),
                     default=None, help="Region polygon (shapefile, KML, GeoPackage) for peak-list inputs: "
                                        "disks are placed inside it eroded by R."),
        click.option("--isolation", type=click.Path(exists=True, dir_okay=False, path_type=Path), default=None,
                     help="Kirmse & de Ferranti isolation list to join to a Kirmse prominence list."),
    ]):
        f = opt(f)
    return f
