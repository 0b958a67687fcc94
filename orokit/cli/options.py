"""Options and parameter types shared by the orokit commands.

:class:`Length` is the one parser of lengths on the command line: ``90km``, ``500m``,
``30 m``, ``100ft``, ``1.5km``, ``2e3m`` and, where a command documents it, a plain
number of metres. Sizes ``WxH`` (``90x60km``, ``9000 x 6000 m``) share one unit.
Anything else (``1.2.3km``, ``.``, ``-5km``, ``0m`` unless zero is allowed, ``nan``,
``inf``) is refused with a message naming the option.

The options every command spells the same way are defined here, once:
:func:`min_prominence_option`, :func:`cell_size_option`, :func:`z_units_option`,
:func:`seed_option`, :func:`overwrite_option` and :func:`progress_option`.
"""
from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

__all__ = ["Length", "parse_length", "common_input_options", "min_prominence_option", "cell_size_option",
           "z_units_option", "seed_option", "overwrite_option", "progress_option", "LENGTH", "RADIUS", "SIZE",
           "PROMINENCE", "InputSource", "resolve_input", "INPUT", "refuse_existing", "LonLat", "LONLAT",
           "center_option", "output_frame"]

#: a non-negative decimal number: digits with an optional fraction, or a bare fraction,
#: optionally followed by an exponent; no sign, no second dot
_NUMBER = r"(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?"
_UNIT = r"(km|m|ft)"
_LENGTH = re.compile(rf"^\s*({_NUMBER})\s*{_UNIT}?\s*$", re.IGNORECASE)
_SIZE = re.compile(rf"^\s*({_NUMBER})\s*(?:[xX]\s*({_NUMBER}))?\s*{_UNIT}?\s*$", re.IGNORECASE)
_FACTOR = {"m": 1.0, "km": 1000.0, "ft": 0.3048}


def parse_length(text: str | float, *, allow_bare: bool = True, bare_min_m: float | None = None,
                 pair: bool = False, allow_zero: bool = False, hint: str | None = None) -> Any:
    """Parse a length (or a ``WxH`` size with ``pair=True``) into metres.

    Parameters
    ----------
    text : str or number
        ``"90km"``, ``"500m"``, ``"30 m"``, ``"100ft"`` (x 0.3048); with ``allow_bare`` also
        ``"2500"`` (metres).
        A number (int/float) is taken as metres when ``allow_bare``.
    allow_bare : bool
        Accept numbers without a unit (metres).
    bare_min_m : float, optional
        Refuse a unit-less value below this (catches ``--radius 10`` meant as km).
    pair : bool
        Accept ``WxH`` and return ``(width, height)``; a single length gives a square.
    allow_zero : bool
        Accept 0 (a threshold such as ``--min-prominence 0``); sizes never are 0.
    hint : str, optional
        Option name for the error message.

    Returns
    -------
    float or (float, float)
        Metres, finite and > 0 (>= 0 with ``allow_zero``).

    Raises
    ------
    click.BadParameter
        Anything that is not such a length, or a length <= 0.

    Examples
    --------
    >>> parse_length("90km"), parse_length("30 m"), parse_length("90x60km", pair=True)
    (90000.0, 30.0, (90000.0, 60000.0))
    >>> round(parse_length("100ft"), 6), parse_length("0", allow_zero=True)
    (30.48, 0.0)
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
    if not all(math.isfinite(v) and (v > 0 or (allow_zero and v == 0)) for v in metres):
        kind = "zero or a positive" if allow_zero else "a positive"
        raise click.BadParameter(f"length must be {kind} finite number, got {text!r}", param_hint=hint)
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
    allow_zero : bool
        Accept 0 (thresholds).
    """

    def __init__(self, *, allow_bare: bool = True, bare_min_m: float | None = None, pair: bool = False,
                 allow_zero: bool = False) -> None:
        self.allow_bare = allow_bare
        self.bare_min_m = bare_min_m
        self.pair = pair
        self.allow_zero = allow_zero
        self.name = "SIZE" if pair else "LENGTH"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:  # noqa: D102
        if self.pair and isinstance(value, tuple):
            return value
        try:
            return parse_length(value, allow_bare=self.allow_bare, bare_min_m=self.bare_min_m, pair=self.pair,
                                allow_zero=self.allow_zero, hint=None)
        except click.BadParameter as exc:
            self.fail(exc.message, param, ctx)


#: a length in metres: 30m, 0.03km, 100ft, or a plain number of metres
LENGTH = Length(allow_bare=True)
#: a domain size WxH or one length (square), one unit for both
SIZE = Length(allow_bare=True, pair=True)
#: disk radius: a length with unit; a bare number is metres (>= 100, else it was meant as km)
RADIUS = Length(allow_bare=True, bare_min_m=100.0)
#: a prominence threshold: a length, 0 allowed
PROMINENCE = Length(allow_bare=True, allow_zero=True)

Decorator = Callable[[Callable[..., Any]], Callable[..., Any]]


class LonLat(click.ParamType):
    """Click type of a point ``LON,LAT`` in degrees, one word (``86.9,27.98``, ``-70.1,-33.4``);
    the value is ``(lon, lat)``, lon in [-180, 180] and lat in [-90, 90]."""

    name = "LON,LAT"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:  # noqa: D102
        if isinstance(value, tuple):
            return value
        parts = str(value).split(",")
        try:
            numbers = [float(v) for v in parts]
        except ValueError:
            numbers = []
        if len(numbers) == 1:  # `--center 86.9 27.98`: the two-word form of synthesize-tree before session 18
            self.fail(f"{value!r} is one number: give LON,LAT as one word with a comma, e.g. 86.9,27.98 "
                      "(the two-word form LON LAT is no longer accepted)", param, ctx)
        if len(numbers) != 2:
            self.fail(f"{value!r} is not LON,LAT (e.g. 86.9,27.98)", param, ctx)
        lon, lat = numbers
        if not (math.isfinite(lon) and math.isfinite(lat) and -180 <= lon <= 180 and -90 <= lat <= 90):
            self.fail(f"{value!r} is not a point on Earth: LON in [-180, 180], LAT in [-90, 90] degrees", param, ctx)
        return (lon, lat)


#: a point LON,LAT in degrees, one word
LONLAT = LonLat()


def center_option() -> Decorator:
    """``--center LON,LAT``: the centre of a synthesized domain (``synthesize``, ``synthesize-tree``)."""
    return click.option("--center", type=LONLAT, default=None,
                        help="Domain centre LON,LAT in degrees, one word (e.g. 86.9,27.98): with --crs the domain is "
                             "centred there in that CRS, without it in a local azimuthal-equidistant CRS (written as "
                             "WKT) centred there.")


def output_frame(crs: str | None, center: tuple[float, float] | None) -> tuple[str | None, bool]:
    """The output CRS of ``--crs`` (None for none or ``local``) and whether ``--crs local`` asked for a
    local frame; ``--crs local`` with ``--center`` is refused (a local frame has no place on Earth)."""
    local = crs is not None and str(crs).strip().lower() == "local"
    if local and center is not None:
        raise click.UsageError("--crs local is a frame with no place on Earth: give --center or --crs local, not both")
    return (None if local else crs), local


def min_prominence_option(*, default: str | None = "30m", help: str | None = None,  # noqa: A002
                          zero_keeps_all: bool = True) -> Decorator:
    """``--min-prominence``: the prominence threshold eps as a length (value in metres)."""
    text = help or "Prominence threshold eps: only peaks with prominence >= this count"
    zero = "; 0 keeps every peak" if zero_keeps_all else ""
    return click.option(
        "--min-prominence", "min_prominence_m", type=PROMINENCE, default=default, show_default=default is not None,
        help=f"{text} (a length: 30m, 100ft; a plain number is metres{zero}).")


def cell_size_option(*, help: str | None = None) -> Decorator:  # noqa: A002
    """``--cell-size``: the cell size of a raster without georeference (value in metres)."""
    text = help or "Cell size of a raster without georeference (PNG); gives a local metric grid"
    return click.option("--cell-size", "cell_size_m", type=LENGTH, default=None,
                        help=f"{text} (a length: 92.6m; a plain number is metres).")


def z_units_option(*, help: str | None = None) -> Decorator:  # noqa: A002
    """``--z-units m|ft``: elevation units of an input that does not declare them."""
    return click.option("--z-units", type=click.Choice(["m", "ft"]), default=None,
                        help=help or "Elevation units of an input that does not declare them (required for PNG DEMs).")


def seed_option(*, what: str, default: int | None = 0, recorded_in: str | None = None,
                required: bool = False) -> Decorator:
    """``--seed N``: an int >= 0; the same seed gives the same result.

    ``default=None`` draws fresh entropy, which the command records in ``recorded_in``
    so that the run can be replayed; ``required=True`` has no default.
    """
    if required:
        return click.option("--seed", type=click.IntRange(min=0), required=True,
                            help=f"Random seed of {what}: an integer >= 0; the same seed gives the same result "
                                 f"[default: none, required].")
    if default is None:
        where = f", recorded in {recorded_in}" if recorded_in else ""
        dflt = f"fresh entropy{where}"
    else:
        dflt = str(default)
    return click.option("--seed", type=click.IntRange(min=0), default=default,
                        help=f"Random seed of {what}: an integer >= 0; the same seed gives the same result "
                             f"[default: {dflt}].")


def overwrite_option(what: str = "existing outputs") -> Decorator:
    """``--overwrite``: without it an existing output is kept and the command stops."""
    return click.option("--overwrite", is_flag=True,
                        help=f"Replace {what} (without it, existing outputs are kept and the command stops).")


def progress_option() -> Decorator:
    """``--progress/--no-progress``: progress bars on stderr (on by default; off under ``orokit -q``,
    which prints only errors)."""
    def unless_quiet(ctx: click.Context, param: click.Parameter, value: bool) -> bool:
        return value and not (ctx.find_root().obj or {}).get("quiet")

    return click.option("--progress/--no-progress", default=True, show_default=True, callback=unless_quiet,
                        help="Progress bars on stderr (none with orokit -q).")


def common_input_options(f: Callable[..., Any]) -> Callable[..., Any]:
    """Options shared by ``features`` and ``classify`` to read an input."""
    for opt in reversed([
        z_units_option(help="Elevation units of DEMs without units (PNG) and of Kirmse peak lists (default ft)."),
        cell_size_option(help="Cell size of DEMs without georeference (PNG); gives a local metric grid"),
        click.option("--region", "region", type=click.Path(exists=True, dir_okay=False, path_type=Path),
                     default=None, help="Region polygon (shapefile, KML, GeoPackage) for peak-list inputs: "
                                        "disks are placed inside it eroded by R."),
        click.option("--isolation", type=click.Path(exists=True, dir_okay=False, path_type=Path), default=None,
                     help="Kirmse & de Ferranti isolation list to join to a Kirmse prominence list."),
    ]):
        f = opt(f)
    return f


@dataclasses.dataclass(frozen=True)
class InputSource:
    """A command-line input: a file or folder, or a DEM of the datasets manifest.

    ``orokit data list`` names the manifest DEMs; a name resolves to its cached file
    (fetched first) with the manifest's elevation units and, for rasters without
    georeference (PNG), cell size. An existing path always wins over a name.
    """

    path: Path
    dataset: str | None = None
    z_units: str | None = None
    cell_size_m: float | None = None

    def dem_options(self, z_units: str | None, cell_size_m: float | None) -> tuple[str | None, float | None]:
        """The units and cell size to read this input with: the user's, else the manifest's.

        Raises ``click.UsageError`` when the user's value contradicts the manifest.
        """
        if self.dataset is None:
            return z_units, cell_size_m
        if z_units is not None and self.z_units is not None and z_units != self.z_units:
            raise click.UsageError(f"{self.dataset} is a manifest DEM in {self.z_units}; drop --z-units {z_units}")
        if cell_size_m is not None and self.cell_size_m is not None and not math.isclose(cell_size_m, self.cell_size_m):
            raise click.UsageError(f"{self.dataset} is a manifest DEM with {self.cell_size_m:g} m cells; drop "
                                   f"--cell-size {cell_size_m:g}")
        return (z_units or self.z_units,
                cell_size_m if cell_size_m is not None else self.cell_size_m)

    def read_dem(self, *, z_units: str | None = None, cell_size_m: float | None = None, **kwargs: Any) -> Any:
        """Read the DEM (``orokit.io.dem.read_dem`` keywords); a dataset keeps its name in ``attrs``."""
        if self.dataset is not None:
            from orokit.data import open_dataset_dem

            self.dem_options(z_units, cell_size_m)  # refuses values contradicting the manifest
            return open_dataset_dem(self.dataset, chunks=kwargs.get("chunks"))
        from orokit.io.dem import read_dem

        return read_dem(str(self.path), z_units=z_units, cell_size_m=cell_size_m, **kwargs)

    def __str__(self) -> str:
        """The dataset name, or the path as given."""
        return self.dataset or str(self.path)

    @property
    def label(self) -> str | None:
        """Region label of a dataset (its name), None for a path."""
        return self.dataset


def resolve_input(text: str | Path, *, hint: str = "INPUT") -> InputSource:
    """An existing path, or the name of a DEM of the datasets manifest (the one resolver of
    every command that reads a DEM).

    Raises
    ------
    click.BadParameter
        Neither an existing path nor a manifest DEM (the message lists the DEM names), or
        the dataset cannot be fetched.
    """
    p = Path(text)
    if p.exists():
        return InputSource(p)
    from orokit.data import fetch_file, load_manifest
    from orokit.errors import OrokitError

    man = load_manifest()
    names = [d.name for d in man.dems()]
    if str(text) not in names:
        raise click.BadParameter(f"{str(text)!r} is neither an existing file or folder nor a DEM of the datasets "
                                 f"manifest ({', '.join(names)}; see `orokit data list`)", param_hint=hint)
    ds = man[str(text)]
    try:
        path = fetch_file(ds.primary)
    except OrokitError as exc:
        raise click.BadParameter(f"cannot fetch dataset {ds.name!r}: {exc}", param_hint=hint) from None
    return InputSource(Path(path), dataset=ds.name, z_units=ds.z_units,
                       cell_size_m=ds.cell_size_m if ds.local_grid else None)


class InputParam(click.ParamType):
    """Click type of an input path or manifest DEM name; the value is an :class:`InputSource`."""

    name = "PATH|DATASET"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:  # noqa: D102
        if isinstance(value, InputSource):
            return value
        try:
            return resolve_input(value, hint=param.get_error_hint(ctx) if param is not None and ctx else "INPUT")
        except click.BadParameter as exc:
            self.fail(exc.message, param, ctx)


#: a path (file or folder) or the name of a manifest DEM
INPUT = InputParam()


def refuse_existing(*paths: Path | None, overwrite: bool) -> None:
    """Stop (usage error, exit 2) when one of ``paths`` exists and ``--overwrite`` was not given."""
    if overwrite:
        return
    existing = [str(p) for p in paths if p is not None and Path(p).exists()]
    if existing:
        raise click.UsageError(f"{', '.join(existing)} already exist{'s' if len(existing) == 1 else ''}; "
                               f"pass --overwrite to replace {'it' if len(existing) == 1 else 'them'}")
