"""Divide Tree files in the reference TXT format.

The TXT format is the one of the Divide Trees shipped with Argudo et al. (2019) (a
modified output of Kirmse's prominence program). It is plain text, one section after
the other, each a header line ``<Name> <count>`` followed by ``count`` lines:

* ``Peaks N``: ``id a b elev x y`` (1-based ids)
* ``PromSaddles M``: ``id a b elev x y`` (the saddles of the tree)
* ``BasinSaddles K``: ``id a b elev x y`` (saddles removed to break cycles)
* ``Runoffs R``: ``id a b elev x y`` (where terrain runs off the DEM edge)
* ``Edges E``: ``peakId otherPeakId saddleId`` (1-based)
* ``RunoffEdges R``: ``peakId runoffIndex`` (1-based peak, 0-based runoff)

``x`` is the column counted from the west edge, ``y`` the row counted from the SOUTH
edge, so the raster cell is ``[H - 1 - y, x]``; ``a = x * c / 3600`` and
``b = y * c / 3600`` with ``c`` the cell size in arc-seconds ("fake degrees").
Elevations are in feet in the reference files.
"""
from __future__ import annotations

import logging
import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from orokit._typing import PathLike
from orokit.errors import InputError
from orokit.io._units import factor_to_metres
from orokit.io.atomic import atomic_open
from orokit.topology.divide_tree import DivideTree
from orokit.topology.tree_checks import check_read_tree

logger = logging.getLogger(__name__)

__all__ = ["read_divide_tree_txt", "write_divide_tree_txt", "METRES_PER_ARCSEC"]

#: ground length of one arc-second used for the reference crops (as the paper's scripts
#: and ``datasets_manifest``): 3-arcsec cells are 92.61 m.
METRES_PER_ARCSEC = 30.87

_POINT_SECTIONS = ("Peaks", "PromSaddles", "BasinSaddles", "Runoffs")
_PAIR_SECTIONS = {"Edges": 3, "RunoffEdges": 2}
_SECTION_ORDER = ("Peaks", "PromSaddles", "BasinSaddles", "Runoffs", "Edges", "RunoffEdges")
_RAW_COLUMNS = ["txt_id", "a", "b", "px", "py"]


# ---------------------------------------------------------------------- TXT reading
def _parse_sections(path: Path) -> dict[str, list[tuple[int, list[str]]]]:
    """Split the file into sections of (line number, tokens), checking every count.

    Lines are accumulated as they are read, so an absurd count in a header never
    allocates anything: a short file fails with the line where it ended.
    """
    sections: dict[str, list[tuple[int, list[str]]]] = {}
    name: str | None = None
    expected = 0
    header_line = 0
    lineno = 0
    with open(path, encoding="utf-8", errors="strict") as fh:
        try:
            lines = iter(fh)
            for lineno, raw in enumerate(lines, start=1):
                tokens = raw.split()
                if not tokens:
                    continue
                if name is not None and len(sections[name]) < expected:
                    sections[name].append((lineno, tokens))
                    continue
                # a header is expected here
                if len(tokens) != 2 or tokens[0] not in _SECTION_ORDER:
                    raise InputError(
                        f"{path}:{lineno}: expected a section header '<Name> <count>' with Name one of "
                        f"{', '.join(_SECTION_ORDER)}; got {raw.strip()[:80]!r}. The file is corrupt or "
                        "not a Divide Tree TXT file."
                    )
                if tokens[0] in sections:
                    raise InputError(f"{path}:{lineno}: section {tokens[0]} appears twice")
                try:
                    expected = int(tokens[1])
                except ValueError:
                    expected = -1
                if expected < 0:
                    raise InputError(
                        f"{path}:{lineno}: section {tokens[0]} has count {tokens[1]!r}; "
                        "a count must be a non-negative integer"
                    )
                name, header_line = tokens[0], lineno
                sections[name] = []
        except UnicodeDecodeError as exc:
            raise InputError(f"{path}: not a text file ({exc}); expected a Divide Tree TXT file") from None
    if name is not None and len(sections[name]) < expected:
        raise InputError(
            f"{path}:{lineno}: file ends inside section {name} (header at line {header_line} declares "
            f"{expected} lines, found {len(sections[name])}); the file is truncated"
        )
    return sections


#: largest id or pixel coordinate a TXT tree may hold
_MAX_INDEX = 2**31 - 1


def _points_frame(path: Path, name: str, rows: list[tuple[int, list[str]]]) -> pd.DataFrame:
    data = np.empty((len(rows), 6), dtype=float)
    for i, (lineno, tokens) in enumerate(rows):
        if len(tokens) != 6:
            raise InputError(
                f"{path}:{lineno}: a {name} line needs 6 fields 'id a b elev x y'; got {len(tokens)}: "
                f"{' '.join(tokens)[:80]!r}"
            )
        try:
            data[i] = [float(t) for t in tokens]
        except ValueError:
            raise InputError(f"{path}:{lineno}: non-numeric field in {name} line {' '.join(tokens)[:80]!r}") from None
        if not np.all(np.isfinite(data[i])):
            raise InputError(f"{path}:{lineno}: non-finite value in {name} line {' '.join(tokens)[:80]!r}")
        if np.any(np.abs(data[i, [0, 4, 5]]) > _MAX_INDEX):
            raise InputError(
                f"{path}:{lineno}: id, x and y must be integers below 2^31 in {name} line {' '.join(tokens)[:80]!r}"
            )
        if data[i, 0] != int(data[i, 0]) or data[i, 4] != int(data[i, 4]) or data[i, 5] != int(data[i, 5]):
            raise InputError(f"{path}:{lineno}: id, x and y must be integers in {name} line {' '.join(tokens)!r}")
    frame = pd.DataFrame(
        {
            "txt_id": data[:, 0].astype(np.int64),
            "a": data[:, 1],
            "b": data[:, 2],
            "elev_raw": data[:, 3],
            "px": data[:, 4].astype(np.int64),
            "py": data[:, 5].astype(np.int64),
        }
    )
    if frame["txt_id"].duplicated().any():
        dup = int(frame.loc[frame["txt_id"].duplicated(), "txt_id"].iloc[0])
        raise InputError(f"{path}: section {name} repeats id {dup}; ids must be unique")
    return frame


def _pairs(path: Path, name: str, rows: list[tuple[int, list[str]]], width: int) -> tuple[np.ndarray, list[int]]:
    out = np.empty((len(rows), width), dtype=np.int64)
    for i, (lineno, tokens) in enumerate(rows):
        if len(tokens) != width:
            raise InputError(f"{path}:{lineno}: a {name} line needs {width} integer fields; got {' '.join(tokens)[:80]!r}")
        try:
            out[i] = [int(t) for t in tokens]
        except (ValueError, OverflowError):
            raise InputError(f"{path}:{lineno}: non-integer field in {name} line {' '.join(tokens)[:80]!r}") from None
    return out, [ln for ln, _ in rows]


def _lookup(path: Path, ids: pd.Series, values: np.ndarray, lines: list[int], what: str, section: str) -> np.ndarray:
    index = pd.Index(ids.to_numpy())
    pos = index.get_indexer(values)
    if (pos < 0).any():
        bad = int(np.flatnonzero(pos < 0)[0])
        raise InputError(
            f"{path}:{lines[bad]}: {section} refers to {what} id {int(values[bad])}, which is not listed "
            f"(known ids {int(ids.min()) if len(ids) else 'none'}..{int(ids.max()) if len(ids) else ''})"
        )
    return pos.astype(np.int64)


def _infer_cell_arcsec(frames: list[pd.DataFrame]) -> float | None:
    for f in frames:
        sel = f["px"] > 0
        if sel.any():
            est = f.loc[sel, "a"].to_numpy() * 3600.0 / f.loc[sel, "px"].to_numpy()
            return float(np.round(np.median(est), 3))
        sel = f["py"] > 0
        if sel.any():
            est = f.loc[sel, "b"].to_numpy() * 3600.0 / f.loc[sel, "py"].to_numpy()
            return float(np.round(np.median(est), 3))
    return None


def _place(frame: pd.DataFrame, factor: float, cell: float, height: int | None) -> pd.DataFrame:
    """Add x, y, elevation (metres) and row, col (when the height is known)."""
    px = frame["px"].to_numpy()
    py = frame["py"].to_numpy()
    out = pd.DataFrame(index=pd.RangeIndex(len(frame)))
    if height is not None:
        row = (height - 1 - py).astype(np.int64)
        col = px.astype(np.int64)
        out["x"] = (col + 0.5) * cell
        out["y"] = -(row + 0.5) * cell
    else:
        row = col = None
        out["x"] = (px + 0.5) * cell
        out["y"] = (py + 0.5) * cell
    out["elevation"] = frame["elev_raw"].to_numpy() * factor
    if row is not None:
        out["row"] = row
        out["col"] = col
    for c in _RAW_COLUMNS:
        out[c] = frame[c].to_numpy()
    return out


def read_divide_tree_txt(
    path: PathLike,
    *,
    cell_size_m: float | None = None,
    z_units: str = "ft",
    height: int | None = None,
) -> DivideTree:
    """Read a Divide Tree in the reference TXT format.

    Parameters
    ----------
    path
        The ``.txt`` file.
    cell_size_m
        Cell size in metres. ``None`` infers the cell size in arc-seconds from the
        ``a``/``x`` columns and uses :data:`METRES_PER_ARCSEC` metres per arc-second
        (92.61 m for the 3-arcsec reference crops).
    z_units
        Units of the elevations in the file (``"ft"`` for the reference files).
    height
        Raster height H in cells. When given, peaks and saddles get 0-based ``row``
        (row 0 at the top: ``row = H - 1 - y``) and ``col``, and ``x``/``y`` are on the
        local grid of :func:`orokit.io.dem.read_dem` (origin at the north-west corner,
        ``x = (col + 0.5) * cell``, ``y = -(row + 0.5) * cell``). Without it ``x``/``y``
        are measured from the south-west corner (``y = (y_px + 0.5) * cell``).

    Returns
    -------
    DivideTree
        Elevations in metres; raw file values kept in the columns ``txt_id``, ``a``,
        ``b``, ``px``, ``py``. ``attrs`` holds ``runoffs`` (DataFrame, with the peak
        ``txt_id`` each runoff belongs to in ``peak_txt_id``), ``basin_saddles``
        (DataFrame), ``height``, ``cell_size_m`` (m), ``cell_size_arcsec``, ``z_units_in``
        and ``source``. Runoffs are not peaks.

    Raises
    ------
    InputError
        Truncated or corrupt file (the message names the line), unknown ids in the
        edges, or a cell size that cannot be inferred.
    DivideTreeError
        The content is no Divide Tree (see
        :func:`orokit.topology.tree_checks.check_read_tree`; the file's ids are quoted).
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"Divide Tree file {path} does not exist or is not a file")
    factor = factor_to_metres(z_units)
    sections = _parse_sections(path)
    frames = {n: _points_frame(path, n, sections.get(n, [])) for n in _POINT_SECTIONS}
    for required in ("Peaks", "PromSaddles", "Edges"):
        if required not in sections:
            raise InputError(
                f"{path}: missing section {required!r} (found {sorted(sections) or 'none'}); "
                "a Divide Tree TXT file needs at least Peaks, PromSaddles and Edges"
            )
    arcsec = _infer_cell_arcsec(list(frames.values()))
    if cell_size_m is None:
        if arcsec is None:
            raise InputError(
                f"{path}: cannot infer the cell size (every point has x = y = 0); pass cell_size_m= in metres"
            )
        cell = arcsec * METRES_PER_ARCSEC
    else:
        cell = float(cell_size_m)
        if not (math.isfinite(cell) and cell > 0):
            raise InputError(f"cell_size_m must be a positive number of metres; got {cell_size_m!r}")
    if height is not None:
        height = int(height)
        too_high = max((int(f["py"].max()) for f in frames.values() if len(f)), default=-1)
        if height <= too_high:
            raise InputError(
                f"{path}: height={height} but the file has points at y = {too_high} (rows from the south); "
                "pass the raster height of the DEM the tree was computed on"
            )
    peaks = _place(frames["Peaks"], factor, cell, height)
    saddles = _place(frames["PromSaddles"], factor, cell, height)

    raw_edges, edge_lines = _pairs(path, "Edges", sections["Edges"], 3)
    a = _lookup(path, frames["Peaks"]["txt_id"], raw_edges[:, 0], edge_lines, "peak", "Edges")
    b = _lookup(path, frames["Peaks"]["txt_id"], raw_edges[:, 1], edge_lines, "peak", "Edges")
    s = _lookup(path, frames["PromSaddles"]["txt_id"], raw_edges[:, 2], edge_lines, "saddle", "Edges")
    edges = pd.DataFrame({"peak_a": a, "peak_b": b, "saddle": s})

    runoffs = _place(frames["Runoffs"], factor, cell, height)
    runoffs["peak_txt_id"] = np.full(len(runoffs), -1, np.int64)
    if "RunoffEdges" in sections:
        raw_re, re_lines = _pairs(path, "RunoffEdges", sections["RunoffEdges"], 2)
        _lookup(path, frames["Peaks"]["txt_id"], raw_re[:, 0], re_lines, "peak", "RunoffEdges")
        idx = raw_re[:, 1]
        bad = (idx < 0) | (idx >= len(runoffs))
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise InputError(
                f"{path}:{re_lines[i]}: RunoffEdges refers to runoff index {int(idx[i])}; "
                f"valid indices are 0..{len(runoffs) - 1}"
            )
        runoffs.loc[idx, "peak_txt_id"] = raw_re[:, 0]
    attrs: dict[str, Any] = {
        "source": str(path),
        "z_units_in": z_units,
        "units": "m",
        "cell_size_m": cell,
        "cell_size_arcsec": arcsec if cell_size_m is None else cell / METRES_PER_ARCSEC,
        "height": height,
        "local_grid": True,
        "runoffs": runoffs,
        "basin_saddles": _place(frames["BasinSaddles"], factor, cell, height),
    }
    tree = check_read_tree(DivideTree(peaks, saddles, edges, None, attrs), str(path), id_column="txt_id")
    logger.info("read %s: %d peaks, %d saddles, %d runoffs", path, tree.n_peaks, tree.n_saddles, len(runoffs))
    return tree


# ---------------------------------------------------------------------- TXT writing
def _raw_points(frame: pd.DataFrame, height: int | None, cell: float | None, arcsec: float | None, what: str) -> pd.DataFrame:
    """Pixel x (from west), y (from south) and a/b for every point of ``frame``."""
    n = len(frame)
    if {"px", "py"} <= set(frame.columns):
        px, py = frame["px"].to_numpy(np.int64), frame["py"].to_numpy(np.int64)
    elif {"row", "col"} <= set(frame.columns):
        if height is None:
            raise InputError(
                f"cannot write {what} to TXT: rows are counted from the south there, so the raster height is "
                "needed; pass height= (or set tree.attrs['height'])"
            )
        px = frame["col"].to_numpy(np.int64)
        py = height - 1 - frame["row"].to_numpy(np.int64)
    else:
        if cell is None or height is None:
            raise InputError(
                f"cannot write {what} to TXT: no px/py or row/col columns; pass height= and cell_size_m= so x/y "
                "(local grid, origin at the north-west corner) can be turned into cells"
            )
        px = np.floor(frame["x"].to_numpy(float) / cell).astype(np.int64)
        py = height - 1 - np.floor(-frame["y"].to_numpy(float) / cell).astype(np.int64)
    if {"a", "b"} <= set(frame.columns):
        a, b = frame["a"].to_numpy(float), frame["b"].to_numpy(float)
    else:
        c = arcsec if arcsec is not None else 1.0
        a, b = px * c / 3600.0, py * c / 3600.0
    ids = np.arange(1, n + 1, dtype=np.int64)
    return pd.DataFrame({"id": ids, "a": a, "b": b, "px": px, "py": py, "elevation": frame["elevation"].to_numpy(float)})


def _fmt_elev(v: float) -> str:
    if not math.isfinite(v):
        raise InputError(f"cannot write a non-finite elevation ({v}) to a Divide Tree TXT file")
    r = round(v)
    return str(int(r)) if abs(v - r) < 1e-6 * max(1.0, abs(v)) else f"{v:.10g}"


def _point_lines(name: str, raw: pd.DataFrame, factor: float) -> list[str]:
    lines = [f"{name} {len(raw)}"]
    for i, a, b, e, x, y in zip(raw["id"], raw["a"], raw["b"], raw["elevation"], raw["px"], raw["py"]):
        lines.append(f"{i} {a:.6f} {b:.6f} {_fmt_elev(e / factor)} {x} {y}")
    return lines


def write_divide_tree_txt(
    tree: DivideTree,
    path: PathLike,
    *,
    z_units: str = "ft",
    height: int | None = None,
    cell_size_m: float | None = None,
) -> Path:
    """Write ``tree`` in the reference TXT format (atomically).

    Parameters
    ----------
    tree
        The Divide Tree (elevations in metres).
    path
        Output file.
    z_units
        Units of the written elevations (``"ft"`` as the reference files).
    height, cell_size_m
        Raster height in cells and cell size in metres, needed to turn ``row``/``col``
        (or local-grid ``x``/``y``) into the file's pixel coordinates when the tree was
        not read from a TXT file. Default: ``tree.attrs["height"]`` /
        ``tree.attrs["cell_size_m"]``.

    Notes
    -----
    Ids are renumbered 1..n in the tree's order. ``a``/``b`` are kept from a tree read
    from TXT, else computed as ``x * c / 3600`` with ``c`` = cell size in arc-seconds
    (``cell_size_m / 30.87``). Runoffs and basin saddles from ``tree.attrs`` are written
    when present; runoffs of peaks no longer in the tree (after pruning) are dropped.
    """
    factor = factor_to_metres(z_units)
    height = height if height is not None else tree.attrs.get("height")
    cell = cell_size_m if cell_size_m is not None else tree.attrs.get("cell_size_m")
    arcsec = tree.attrs.get("cell_size_arcsec")
    if arcsec is None and cell is not None:
        arcsec = float(cell) / METRES_PER_ARCSEC
    tree.validate(check_elevations=False)
    peaks = _raw_points(tree.peaks, height, cell, arcsec, "peaks")
    saddles = _raw_points(tree.saddles, height, cell, arcsec, "saddles")
    basin = tree.attrs.get("basin_saddles")
    basin_raw = _raw_points(basin, height, cell, arcsec, "basin saddles") if isinstance(basin, pd.DataFrame) else peaks.iloc[:0]
    runoffs = tree.attrs.get("runoffs")
    runoff_edges: list[tuple[int, int]] = []
    if isinstance(runoffs, pd.DataFrame) and len(runoffs) and "txt_id" in tree.peaks.columns and "peak_txt_id" in runoffs.columns:
        pos = pd.Index(tree.peaks["txt_id"].to_numpy()).get_indexer(runoffs["peak_txt_id"].to_numpy())
        runoffs = runoffs[pos >= 0].reset_index(drop=True)
        runoff_edges = [(int(p) + 1, i) for i, p in enumerate(pos[pos >= 0])]
        runoff_raw = _raw_points(runoffs, height, cell, arcsec, "runoffs")
    else:
        runoff_raw = peaks.iloc[:0]
    lines = _point_lines("Peaks", peaks, factor)
    lines += _point_lines("PromSaddles", saddles, factor)
    lines += _point_lines("BasinSaddles", basin_raw, factor)
    lines += _point_lines("Runoffs", runoff_raw, factor)
    e = tree.edges
    lines.append(f"Edges {len(e)}")
    lines += [f"{a + 1} {b + 1} {s + 1}" for a, b, s in zip(e["peak_a"], e["peak_b"], e["saddle"])]
    lines.append(f"RunoffEdges {len(runoff_edges)}")
    lines += [f"{p} {r}" for p, r in runoff_edges]
    with atomic_open(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write("\n".join(lines) + "\n")
    logger.info("wrote %s: %d peaks, %d ridges", path, tree.n_peaks, len(e))
    return Path(path)
