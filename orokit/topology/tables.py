"""Result types and table schemas of the orometry (a leaf module: imports nothing above it).

The peaks table is written by the raster analysis (:func:`orokit.analyze`), by Divide
Tree synthesis (:func:`orokit.synthesis.peaks_table`) and read back from files; its
columns, dtypes, units and "none" values are defined here once (:data:`PEAK_SCHEMA`)
and checked by :func:`validate_peak_table`.

"None" values: integer columns (raster cells and peak ids) hold ``-1``
(:data:`NONE_ID`), float columns hold NaN. A synthesized tree has no raster, so its
``row``/``col`` columns are -1 throughout.
"""
from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from orokit.errors import SchemaError
from orokit.geodesy import cell_size_key
from orokit.topology.divide_tree import DivideTree

if TYPE_CHECKING:
    import pandas as pd

__all__ = [
    "Column", "PEAK_SCHEMA", "PEAK_COLUMNS", "OROMETRY_COLUMNS", "SADDLE_SCHEMA", "SADDLE_COLUMNS", "NONE_ID",
    "AnalysisResult", "CellPlaces", "TableBlocks", "table_rows", "validate_peak_table", "validate_saddle_table", "upgrade_attrs",
]

#: "none" of every integer column (raster cell, peak id)
NONE_ID = -1


def upgrade_attrs(attrs: Any, *, geographic: bool | None = None) -> dict[str, Any]:
    """Metadata read from a file, with the keys of files written before orokit's naming rules.

    ``min_prominence`` becomes ``min_prominence_m``; ``cell_size`` becomes ``cell_size_deg`` on a
    geographic grid (``geographic``, else the attrs' own ``crs_geographic``), else ``cell_size_m``;
    the former pair ``res`` is dropped when the cell size is known. A current key always wins.

    >>> upgrade_attrs({"min_prominence": 30.0, "cell_size": [92.6, 92.6]})
    {'min_prominence_m': 30.0, 'cell_size_m': [92.6, 92.6]}
    """
    out = dict(attrs or {})
    if "min_prominence" in out:
        value = out.pop("min_prominence")
        out.setdefault("min_prominence_m", value)
    if "cell_size" in out:
        value = out.pop("cell_size")
        geo = bool(out.get("crs_geographic", False)) if geographic is None else geographic
        out.setdefault(cell_size_key(geo), value)
    if "res" in out and ("cell_size_m" in out or "cell_size_deg" in out):
        out.pop("res")
    return out


@dataclass(frozen=True)
class Column:
    """One column of a table schema."""

    name: str
    dtype: Literal["int64", "float64", "bool"]
    unit: str
    doc: str

    @property
    def none(self) -> float | int | None:
        """The value meaning "none" in this column (-1, NaN, or None for flags)."""
        return {"int64": NONE_ID, "float64": float("nan")}.get(self.dtype)


#: Columns of the peaks table, in order (index ``peak_id``, int64, 0..n-1).
#: Coordinates are cell centres; row/col are 0-based with row 0 at the top.
PEAK_SCHEMA: tuple[Column, ...] = (
    Column("row", "int64", "cell", "raster row of the peak (first cell in raster order of a flat summit)"),
    Column("col", "int64", "cell", "raster column of the peak"),
    Column("x", "float64", "crs", "x of the peak in the table's CRS"),
    Column("y", "float64", "crs", "y of the peak in the table's CRS"),
    Column("lon", "float64", "deg", "WGS84 longitude (NaN without CRS)"),
    Column("lat", "float64", "deg", "WGS84 latitude (NaN without CRS)"),
    Column("elevation", "float64", "m", "elevation of the peak"),
    Column("prominence", "float64", "m", "elder-rule prominence (elevation for a domain's highest peak)"),
    Column("saddle_row", "int64", "cell", "raster row of the key saddle"),
    Column("saddle_col", "int64", "cell", "raster column of the key saddle"),
    Column("saddle_x", "float64", "crs", "x of the key saddle"),
    Column("saddle_y", "float64", "crs", "y of the key saddle"),
    Column("saddle_elevation", "float64", "m", "elevation of the key saddle"),
    Column("island_parent", "int64", "peak_id", "island parent: highest peak joined at the key saddle"),
    Column("island_parent_row", "int64", "cell", "raster row of the island parent"),
    Column("island_parent_col", "int64", "cell", "raster column of the island parent"),
    Column("line_parent", "int64", "peak_id",
           "first higher peak on the walk down to the key saddle and up the other side (depends on eps)"),
    Column("line_parent_row", "int64", "cell", "raster row of the line parent"),
    Column("line_parent_col", "int64", "cell", "raster column of the line parent"),
    Column("prominence_parent", "int64", "peak_id", "first more prominent peak on that walk"),
    Column("prominence_parent_row", "int64", "cell", "raster row of the prominence parent"),
    Column("prominence_parent_col", "int64", "cell", "raster column of the prominence parent"),
    Column("dominance", "float64", "1", "prominence / elevation (NaN when elevation <= 0)"),
    Column("isolation", "float64", "m", "distance to the nearest strictly higher ground"),
    Column("isolation_row", "int64", "cell", "raster row of that higher ground"),
    Column("isolation_col", "int64", "cell", "raster column of that higher ground"),
    Column("isolation_x", "float64", "crs", "x of that higher ground"),
    Column("isolation_y", "float64", "crs", "y of that higher ground"),
    Column("prominence_exact", "bool", "", "False when terrain outside the data could lower the prominence"),
    Column("isolation_exact", "bool", "", "False when the edge or nodata is closer than the higher ground"),
)
PEAK_COLUMNS: list[str] = [c.name for c in PEAK_SCHEMA]
#: the columns derived from the tree and the raster (everything but the peak's own place and height)
OROMETRY_COLUMNS: list[str] = [c for c in PEAK_COLUMNS if c not in ("row", "col", "x", "y", "elevation")]

#: Columns of the saddles table (index ``saddle_id``): the saddles of the pruned Divide Tree.
SADDLE_SCHEMA: tuple[Column, ...] = (
    Column("row", "int64", "cell", "raster row of the saddle"),
    Column("col", "int64", "cell", "raster column of the saddle"),
    Column("x", "float64", "crs", "x of the saddle"),
    Column("y", "float64", "crs", "y of the saddle"),
    Column("elevation", "float64", "m", "elevation of the saddle"),
    Column("key_of", "int64", "peak_id", "a peak whose key saddle it is (a monkey saddle may serve several)"),
)
SADDLE_COLUMNS: list[str] = [c.name for c in SADDLE_SCHEMA]


def _validate(table: Any, schema: tuple[Column, ...], index: str, what: str, source: str | None) -> None:
    import pandas as pd

    where = f"{source}: " if source else ""
    if isinstance(table, TableBlocks):  # its first block: every block has the same columns and dtypes
        table = table.block(0, 1 << 16)
    if not isinstance(table, pd.DataFrame):
        raise SchemaError(f"{where}the {what} table must be a (Geo)DataFrame, got {type(table).__name__}")
    missing = [c.name for c in schema if c.name not in table.columns]
    if missing:
        raise SchemaError(f"{where}the {what} table lacks columns {missing}; "
                          f"re-create it with this orokit version (e.g. rerun `orokit analyze`)")
    if table.index.name != index:
        raise SchemaError(f"{where}the {what} table must be indexed by {index!r}, got {table.index.name!r}")
    bad = []
    for c in schema:
        s = table[c.name]
        ok = {"int64": pd.api.types.is_integer_dtype, "float64": pd.api.types.is_float_dtype,
              "bool": pd.api.types.is_bool_dtype}[c.dtype](s.dtype)
        if not ok:
            bad.append(f"{c.name} ({s.dtype}, expected {c.dtype})")
        elif c.dtype == "int64" and len(s) and int(s.min()) < NONE_ID:
            bad.append(f"{c.name} (value {int(s.min())} below the 'none' value {NONE_ID})")
    if bad:
        raise SchemaError(f"{where}the {what} table has bad columns: {', '.join(bad)}")


def validate_peak_table(peaks: Any, *, source: str | None = None) -> None:
    """Check a peaks table against :data:`PEAK_SCHEMA` (columns, dtypes, "none" values).

    Extra columns are allowed. ``source`` (a file name) is named in the error.

    Raises
    ------
    SchemaError
        A column is missing or has the wrong dtype, an id is below -1, or the index
        is not ``peak_id``.

    Examples
    --------
    >>> import pandas as pd
    >>> validate_peak_table(pd.DataFrame({"row": [0]}), source="p.csv")
    Traceback (most recent call last):
    ...
    orokit.errors.SchemaError: p.csv: the peaks table lacks columns ['col', ...
    """
    _validate(peaks, PEAK_SCHEMA, "peak_id", "peaks", source)


def validate_saddle_table(saddles: Any, *, source: str | None = None) -> None:
    """Check a saddles table against :data:`SADDLE_SCHEMA` (see :func:`validate_peak_table`)."""
    _validate(saddles, SADDLE_SCHEMA, "saddle_id", "saddles", source)


class CellPlaces:
    """``row``, ``col``, ``x``, ``y`` and ``elevation`` of raster points made from their flat cells and
    elevations when asked (8 bytes per point for the cells, instead of 40 for the five columns held).

    ``cell``: flat cells (row * width + col); ``z``: their elevations (given as float64 from any float
    type, exactly); ``transform``: the grid's affine (a, b, c, d, e, f); a point is its cell's centre.
    Every value is the same, bit for bit, however the points are taken (whole, by slices, gathered).
    """

    NAMES = ("row", "col", "x", "y", "elevation")

    def __init__(self, cell: np.ndarray, z: np.ndarray, width: int, transform: Any) -> None:
        self.cell, self.z, self.width = cell, z, int(width)
        self._t = tuple(float(v) for v in tuple(transform)[:6])

    def __len__(self) -> int:
        return int(self.cell.size)

    def values(self, name: str, at: Any = slice(None)) -> np.ndarray:
        """Column ``name`` of the points ``at`` (a slice or an array of positions), as a new array."""
        if name == "elevation":
            return self.z[at].astype(np.float64)
        cell = self.cell[at]
        if name == "row":
            return cell // self.width
        if name == "col":
            return cell % self.width
        if name not in ("x", "y"):
            raise KeyError(name)
        a, b, c, d, e, f = self._t
        out = np.empty(cell.size)
        for s0 in range(0, cell.size, 1 << 18):  # by blocks: the whole arrays' temporaries were ~16 B per point
            part = cell[s0:s0 + (1 << 18)]
            r, k = part // self.width, part % self.width
            out[s0:s0 + part.size] = (c + (k + 0.5) * a + (r + 0.5) * b) if name == "x" else (f + (k + 0.5) * d
                                                                                            + (r + 0.5) * e)
        return out

    def frame(self, start: int, stop: int, index_name: str | None = None,
              more: dict[str, np.ndarray] | None = None) -> pd.DataFrame:
        """The points ``start:stop`` as a DataFrame of :data:`NAMES` (then ``more``'s columns, whole
        arrays sliced), index ``start..stop - 1`` named ``index_name``."""
        import pandas as pd

        sl = slice(start, stop)
        columns = {name: self.values(name, sl) for name in self.NAMES}
        columns.update((name, values[sl]) for name, values in (more or {}).items())
        return pd.DataFrame(columns, index=pd.RangeIndex(start, stop, name=index_name), copy=False)


class TableBlocks:
    """A table whose rows are made block by block when read (a table larger than memory).

    ``make(start, stop)`` returns the DataFrame of rows ``start:stop`` (index named
    ``index_name``, values ``start..stop-1``); every block has the same columns and
    dtypes. ``shared``: whole columns already held elsewhere (returned without making
    blocks). ``places``: a :class:`CellPlaces` of the rows, whose columns are made from it
    alone (whole or at some rows, :meth:`take`) without making blocks. Columns set with
    ``table[name] = values`` (whole arrays) are appended to every block. Writers take the
    rows with :meth:`blocks`; ``table[name]`` gives one whole column; :meth:`to_frame` the
    whole table (all of it in memory).
    """

    def __init__(self, n: int, make: Callable[[int, int], pd.DataFrame], *, index_name: str,
                 shared: dict[str, np.ndarray] | None = None, places: CellPlaces | None = None) -> None:
        self._n = int(n)
        self._make = make
        self.index_name = index_name
        self._shared = dict(shared or {})
        self._places = places
        self._extra: dict[str, np.ndarray] = {}

    def __len__(self) -> int:
        return self._n

    def block(self, start: int, stop: int) -> pd.DataFrame:
        """Rows ``start:stop`` (clipped to the table) as a DataFrame."""
        start, stop = max(0, int(start)), min(self._n, int(stop))
        frame = self._make(start, max(start, stop))
        for name, values in self._extra.items():
            frame[name] = values[start:stop]
        return frame

    def blocks(self, rows: int) -> Iterator[pd.DataFrame]:
        """The table in blocks of ``rows`` rows (one empty block for an empty table)."""
        for start in range(0, max(self._n, 1), rows):
            yield self.block(start, start + rows)

    @property
    def columns(self) -> list[str]:
        return list(self.block(0, 0).columns)

    def __getitem__(self, name: str) -> pd.Series:
        """One whole column (made block by block unless shared or set)."""
        import pandas as pd

        if name in self._extra:
            values = self._extra[name]
        elif name in self._shared:
            values = self._shared[name]
        elif self._places is not None and name in CellPlaces.NAMES:
            values = self._places.values(name)
        else:
            step = 1 << 16
            values = np.concatenate([b[name].to_numpy() for b in self.blocks(step)])
        index = pd.RangeIndex(self._n, name=self.index_name)
        return pd.Series(values, index=index, name=name, copy=False)

    def take(self, name: str, at: np.ndarray) -> np.ndarray:
        """Column ``name`` at the rows ``at`` (positions), without its whole column when the table's
        places, shared or set columns hold it."""
        if name in self._extra:
            return self._extra[name][at]
        if name in self._shared:
            return self._shared[name][at]
        if self._places is not None and name in CellPlaces.NAMES:
            return self._places.values(name, at)
        return self[name].to_numpy()[at]

    def __setitem__(self, name: str, values: Any) -> None:
        values = np.asarray(values)
        if values.shape != (self._n,):
            raise ValueError(f"column {name!r} needs {self._n} values, got shape {values.shape}")
        self._extra[name] = values

    def to_frame(self) -> pd.DataFrame:
        """The whole table as one DataFrame."""
        return self.block(0, self._n)


def table_rows(table: Any, start: int, stop: int) -> pd.DataFrame:
    """Rows ``start:stop`` of a (Geo)DataFrame or a :class:`TableBlocks` as a (Geo)DataFrame."""
    if isinstance(table, TableBlocks):
        return table.block(start, stop)
    return table.iloc[start:stop]


@dataclass
class AnalysisResult:
    """Output of :func:`orokit.analyze` (write it with :func:`orokit.write_analysis`).

    Attributes
    ----------
    peaks : GeoDataFrame indexed by ``peak_id`` with :data:`PEAK_COLUMNS` (:data:`PEAK_SCHEMA`);
        a plain DataFrame (no point geometry) from ``analyze(geometry=False)``; a
        :class:`TableBlocks` (rows made by blocks when written) from ``analyze(blocks=True)``.
    saddles : GeoDataFrame (or DataFrame) indexed by ``saddle_id`` with :data:`SADDLE_COLUMNS`;
        a :class:`TableBlocks` from ``analyze(blocks=True)``.
    tree : the Divide Tree pruned at the threshold (same ids); from ``analyze(blocks=True)`` its
        ``peaks`` and ``saddles`` are TableBlocks of their places (:class:`CellPlaces`).
    crs : CRS of x/y (None for a local metric grid without CRS).
    attrs : metadata (threshold, outside convention, units, source, dataset, shape,
        ``transform`` (affine a, b, c, d, e, f of the grid), ``crs_geographic``, timings).
    depressions : GeoDataFrame of the depressions (``analyze(depressions=True)``;
        :data:`orokit.topology.depressions.DEPRESSION_COLUMNS`), else None.
    """

    peaks: Any
    saddles: Any
    tree: DivideTree
    crs: Any = None
    attrs: dict = field(default_factory=dict)
    depressions: Any = None

    def __repr__(self) -> str:  # pragma: no cover - cosmetic
        return (
            f"AnalysisResult({len(self.peaks)} peaks >= {self.attrs.get('min_prominence_m')} m, "
            f"{len(self.saddles)} saddles, crs={self.crs})"
        )

