"""Andrew Kirmse's ``mountains`` text formats: peak lists and divide trees (``.dvt``).

- **Peak list** (``results.txt`` of ``merge_divide_trees``): one peak per line,
  ``lat,lng,elevation,saddle_lat,saddle_lng,prominence`` (degrees, the tree's units);
  a landmass high point has saddle ``0,0``. The output of ``compute_parents`` has 12
  fields per line: the same six (elevation and prominence swapped in place:
  ``lat,lng,col_lat,col_lng,elevation,prominence``), then the prominence parent's
  ``lat,lng,prominence`` and the line parent's ``lat,lng,elevation``, after a ``#``
  comment and a ``Command line:`` line.
- **Isolation list** (Kirmse & de Ferranti's published lists): ``lat,lng,elevation,
  ilp_lat,ilp_lng,isolation_km`` (ILP: the isolation limit point).
- **Divide tree** (``.dvt``): ``#`` comments, a coordinate-system line (``G,min_lat,
  min_lng,samples_per_deg_lat,samples_per_deg_lng,max_lat,max_lng`` or ``U,zone,min_x,
  min_y,max_x,max_y,metres_per_sample``), then ``P,id,x,y,elevation`` (ids from 1),
  ``S,id,type,x,y,elevation`` (type ``p`` key saddle, ``b`` basin saddle), ``R,...``
  runoffs, and ``N,index,parent_peak,saddle`` (index 0 unused; -1 = none): each peak
  points to its neighbour towards its tree's root through a saddle. x, y are sample
  offsets (y grows southwards).

Formats learned from the program's documentation and output; the reader and writer are
orokit's own. Every reader checks the input and names the file and line on an error.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from orokit._typing import PathLike
from orokit.errors import DivideTreeError, InputError
from orokit.io.atomic import write_text_atomic
from orokit.topology.divide_tree import DivideTree

__all__ = ["KIRMSE_PEAK_COLUMNS", "KIRMSE_PARENT_COLUMNS", "KIRMSE_ISOLATION_COLUMNS", "read_kirmse_peaks",
           "read_kirmse_isolation", "is_kirmse_list", "write_kirmse_peaks", "kirmse_columns",
           "read_kirmse_tree", "write_kirmse_tree"]

#: columns of a ``results.txt`` peak list
KIRMSE_PEAK_COLUMNS = ["lat", "lon", "elevation", "saddle_lat", "saddle_lon", "prominence"]
#: columns of a ``compute_parents`` output (order of the file)
KIRMSE_PARENT_COLUMNS = ["lat", "lon", "saddle_lat", "saddle_lon", "elevation", "prominence",
                         "prominence_parent_lat", "prominence_parent_lon", "prominence_parent_prominence",
                         "line_parent_lat", "line_parent_lon", "line_parent_elevation"]
#: columns of an isolation list (Kirmse & de Ferranti's published lists)
KIRMSE_ISOLATION_COLUMNS = ["lat", "lon", "elevation", "ilp_lat", "ilp_lon", "isolation_km"]


def _numbers(path: Path, lineno: int, fields: list[str]) -> list[float]:
    try:
        values = [float(f) for f in fields]
    except ValueError:
        raise InputError(f"{path}:{lineno}: line {lineno} is not numbers separated by commas: {','.join(fields)!r}; "
                         "is this a Kirmse results.txt / compute_parents file?") from None
    if not all(np.isfinite(values)):
        raise InputError(f"{path}:{lineno}: non-finite value in {','.join(fields)!r}")
    return values


def _read_lines(path: Path, widths: tuple[int, ...], what: str) -> tuple[list[list[float]], int | None]:
    """Numeric comma-separated lines of ``path`` (``#`` and ``Command line:`` lines skipped)."""
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read the Kirmse {what} {path}: {exc}") from None
    rows, width = [], None
    for lineno, line in enumerate(text.splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#") or line.startswith("Command line:"):
            continue
        fields = line.split(",")
        if len(fields) not in widths or (width is not None and len(fields) != width):
            want = " or ".join(str(w) for w in widths) if width is None else str(width)
            raise InputError(f"{path}:{lineno}: {len(fields)} fields (columns), expected {want} (Kirmse {what} layout)")
        width = len(fields)
        rows.append(_numbers(path, lineno, fields))
    return rows, width


def _check_latitudes(path: Path, frame: pd.DataFrame, columns: list[str]) -> None:
    for c in columns:
        bad = ~frame[c].between(-90, 90) & frame[c].notna()
        if bad.any():
            raise InputError(f"{path}: {c} outside [-90, 90] on data line {int(np.flatnonzero(bad.to_numpy())[0]) + 1}; "
                             "Kirmse lists give latitude first (lat,lon,...)")


def read_kirmse_peaks(path: PathLike) -> pd.DataFrame:
    """Peak list of Kirmse's ``results.txt`` (6 fields) or ``compute_parents`` (12 fields).

    Returns a DataFrame with :data:`KIRMSE_PEAK_COLUMNS` (plus the parents' columns of
    :data:`KIRMSE_PARENT_COLUMNS` for a ``compute_parents`` file), in the file's units;
    ``saddle_lat`` and ``saddle_lon`` are NaN where the file writes ``0,0`` or the peak
    itself (a landmass high point).
    """
    path = Path(path)
    rows, width = _read_lines(path, (6, 12), "peak list")
    cols = KIRMSE_PARENT_COLUMNS if width == 12 else KIRMSE_PEAK_COLUMNS
    frame = pd.DataFrame(rows, columns=cols, dtype=float) if rows else pd.DataFrame(columns=cols, dtype=float)
    frame = frame[KIRMSE_PEAK_COLUMNS + [c for c in cols if c not in KIRMSE_PEAK_COLUMNS]]
    none = ((frame["saddle_lat"] == 0) & (frame["saddle_lon"] == 0)) | (
        (frame["saddle_lat"] == frame["lat"]) & (frame["saddle_lon"] == frame["lon"]))
    frame.loc[none, ["saddle_lat", "saddle_lon"]] = np.nan
    _check_latitudes(path, frame, ["lat", "saddle_lat"])
    return frame


def read_kirmse_isolation(path: PathLike) -> pd.DataFrame:
    """Isolation list of Kirmse & de Ferranti: ``lat,lon,elevation,ilp_lat,ilp_lon,isolation_km``.

    Returns a DataFrame with :data:`KIRMSE_ISOLATION_COLUMNS` in the file's units
    (isolation in km).
    """
    path = Path(path)
    rows, _ = _read_lines(path, (6,), "isolation list")
    cols = KIRMSE_ISOLATION_COLUMNS
    frame = pd.DataFrame(rows, columns=cols, dtype=float) if rows else pd.DataFrame(columns=cols, dtype=float)
    _check_latitudes(path, frame, ["lat", "ilp_lat"])
    return frame


def is_kirmse_list(path: PathLike) -> bool:
    """True when the first data line of ``path`` is 6 or 12 comma-separated numbers."""
    with open(path, encoding="utf-8", errors="replace") as fh:
        for line in fh:
            s = line.strip()
            if not s or s.startswith("#") or s.startswith("Command line:"):
                continue
            fields = s.split(",")
            try:
                [float(f) for f in fields]
            except ValueError:
                return False
            return len(fields) in (6, 12)
    return False


def write_kirmse_peaks(peaks: pd.DataFrame, path: PathLike) -> None:
    """Write a peak list in Kirmse's ``results.txt`` format (atomically).

    ``peaks`` needs :data:`KIRMSE_PEAK_COLUMNS` (NaN saddle = none, written ``0,0``);
    an orokit peaks table gets them with :func:`kirmse_columns`.
    """
    missing = [c for c in KIRMSE_PEAK_COLUMNS if c not in peaks.columns]
    if missing:
        raise InputError(f"cannot write {path}: the peak table lacks {missing} (use kirmse_columns() on an "
                         "orokit peaks table)")
    lines = []
    for r in peaks[KIRMSE_PEAK_COLUMNS].itertuples(index=False):
        slat, slon = (0.0, 0.0) if np.isnan(r.saddle_lat) else (r.saddle_lat, r.saddle_lon)
        lines.append(f"{r.lat:.6f},{r.lon:.6f},{r.elevation:.2f},{slat:.6f},{slon:.6f},{r.prominence:.2f}\n")
    write_text_atomic(Path(path), "".join(lines))


def kirmse_columns(peaks) -> pd.DataFrame:
    """:data:`KIRMSE_PEAK_COLUMNS` of an orokit peaks table (GeoDataFrame with a CRS, or lon/lat)."""
    out = pd.DataFrame({"lat": peaks["lat"].to_numpy(float), "lon": peaks["lon"].to_numpy(float),
                        "elevation": peaks["elevation"].to_numpy(float),
                        "prominence": peaks["prominence"].to_numpy(float)})
    crs = getattr(peaks, "crs", None)
    if crs is None or out["lat"].isna().any():
        raise InputError("Kirmse peak lists are in latitude/longitude: the peaks table needs a CRS "
                         "(a raster without georeference has none)")
    from pyproj import Transformer

    sx, sy = peaks["saddle_x"].to_numpy(float), peaks["saddle_y"].to_numpy(float)
    lon, lat = Transformer.from_crs(crs, "EPSG:4326", always_xy=True).transform(sx, sy)
    has = np.isfinite(sx)
    out["saddle_lat"] = np.where(has, lat, np.nan)
    out["saddle_lon"] = np.where(has, lon, np.nan)
    return out[KIRMSE_PEAK_COLUMNS]


def _coordinate_system(path: Path, lineno: int, line: str) -> dict[str, Any]:
    f = line.split(",")
    cs: dict[str, Any]
    try:
        if f[0] == "G" and len(f) >= 5:
            cs = {"kind": "G", "min_lat": float(f[1]), "min_lng": float(f[2]),
                  "samples_lat": int(f[3]), "samples_lng": int(f[4])}
            cs["max_lat"] = float(f[5]) if len(f) >= 7 else cs["min_lat"] + 1
            cs["max_lng"] = float(f[6]) if len(f) >= 7 else cs["min_lng"] + 1
            if cs["samples_lat"] <= 0 or cs["samples_lng"] <= 0:
                raise ValueError
            return cs
        if f[0] == "U" and len(f) >= 7:
            cs = {"kind": "U", "zone": int(f[1]), "min_x": int(f[2]), "min_y": int(f[3]), "max_x": int(f[4]),
                  "max_y": int(f[5]), "metres_per_sample": float(f[6])}
            if cs["metres_per_sample"] <= 0:
                raise ValueError
            return cs
    except ValueError:
        pass
    raise InputError(f"{path}:{lineno}: not a Kirmse coordinate-system line (G,... or U,...): {line!r}")


def read_kirmse_tree(path: PathLike) -> DivideTree:
    """Divide Tree of a Kirmse ``.dvt`` file (runoffs are ignored with their edges).

    Peaks and saddles get ``x``/``y`` = the file's sample offsets (y grows
    southwards), ``lat``/``lon`` from the coordinate system, ``elevation`` and
    ``kirmse_id`` (the file's 1-based id); ``tree.attrs["kirmse_coordinate_system"]``
    keeps the coordinate-system line.
    """
    from orokit.topology.tree_checks import check_read_tree

    path = Path(path)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read the Kirmse divide tree {path}: {exc}") from None
    cs, cs_line = None, ""
    peaks, saddles, nodes = [], [], []
    want = {"P": 5, "S": 6, "N": 4, "R": 7, "E": 3}
    for lineno, line in enumerate(text.splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        if cs is None:
            cs, cs_line = _coordinate_system(path, lineno, line), line
            continue
        f = line.split(",")
        kind = f[0]
        if kind not in want:
            raise InputError(f"{path}:{lineno}: unknown record {kind!r} (expected P, S, R, N or E)")
        if len(f) != want[kind]:
            raise InputError(f"{path}:{lineno}: a {kind} record has {want[kind]} fields, got {len(f)}")
        try:
            if kind == "P":
                peaks.append((int(f[1]), int(f[2]), int(f[3]), float(f[4])))
            elif kind == "S":
                saddles.append((int(f[1]), f[2], int(f[3]), int(f[4]), float(f[5])))
            elif kind == "N":
                nodes.append((int(f[1]), int(f[2]), int(f[3])))
        except ValueError:
            raise InputError(f"{path}:{lineno}: bad number in {line!r}") from None
    if cs is None:
        raise InputError(f"{path}: no coordinate-system line: not a Kirmse .dvt divide tree")
    for what, items in (("peak", peaks), ("saddle", saddles)):
        ids = [t[0] for t in items]
        if ids != list(range(1, len(ids) + 1)):
            raise InputError(f"{path}: {what} ids must run 1, 2, ... in order")
    n, m = len(peaks), len(saddles)
    edges = []
    for idx, parent, saddle in nodes:
        if idx == 0 or parent == -1:
            continue
        if not (1 <= idx <= n and 1 <= parent <= n and 1 <= saddle <= m):
            raise DivideTreeError(f"{path}: node {idx} points to peak {parent} through saddle {saddle}; ids must "
                                  f"lie in 1..{n} (peaks) and 1..{m} (saddles)")
        edges.append((idx - 1, parent - 1, saddle - 1))
    pk = pd.DataFrame(peaks, columns=["kirmse_id", "x", "y", "elevation"]).astype(
        {"kirmse_id": "int64", "x": float, "y": float, "elevation": float})
    sd = pd.DataFrame(saddles, columns=["kirmse_id", "type", "x", "y", "elevation"]).astype(
        {"kirmse_id": "int64", "x": float, "y": float, "elevation": float})
    for frame in (pk, sd):
        frame["lat"], frame["lon"] = _latlon(cs, frame["x"].to_numpy(), frame["y"].to_numpy())
    e = pd.DataFrame(edges, columns=["peak_a", "peak_b", "saddle"], dtype="int64")
    tree = DivideTree(pk, sd, e, None, {"kirmse_coordinate_system": cs_line, "source": str(path)})
    return check_read_tree(tree, str(path), id_column="kirmse_id")


def _latlon(cs: dict[str, Any], x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    if cs["kind"] == "G":
        return cs["max_lat"] - y / cs["samples_lat"], cs["min_lng"] + x / cs["samples_lng"]
    from pyproj import Transformer

    e = cs["min_x"] + x * cs["metres_per_sample"]
    nrt = cs["max_y"] - y * cs["metres_per_sample"]
    zone = abs(cs["zone"])
    epsg = (32700 if cs["zone"] < 0 else 32600) + zone
    lon, lat = Transformer.from_crs(f"EPSG:{epsg}", "EPSG:4326", always_xy=True).transform(e, nrt)
    return np.asarray(lat), np.asarray(lon)


def write_kirmse_tree(tree: DivideTree, path: PathLike, *, coordinate_system: str | None = None) -> None:
    """Write ``tree`` as a Kirmse ``.dvt`` file (atomically).

    ``x``/``y`` of peaks and saddles must be integer sample offsets of
    ``coordinate_system`` (default: ``tree.attrs["kirmse_coordinate_system"]``, as read
    by :func:`read_kirmse_tree`). Each peak points to its neighbour towards the highest
    peak of its part of the tree; key saddles are written ``p``, the others ``b``.
    """
    cs = coordinate_system or tree.attrs.get("kirmse_coordinate_system")
    if not cs:
        raise InputError(f"cannot write {path}: a Kirmse divide tree needs a coordinate-system line "
                         "(coordinate_system='G,...' or 'U,...')")
    _coordinate_system(Path(path), 0, cs)
    tree.validate()
    for name, frame in (("peaks", tree.peaks), ("saddles", tree.saddles)):
        xy = frame[["x", "y"]].to_numpy(float)
        if not np.array_equal(xy, np.round(xy)):
            raise InputError(f"cannot write {path}: {name} x/y must be integer sample offsets")
    n = tree.n_peaks
    a, b, s = (tree.edges[c].to_numpy(np.int64) for c in ("peak_a", "peak_b", "saddle"))
    table = tree.prominence_table()
    key = set(table["key_saddle"][table["key_saddle"] >= 0].tolist())
    # orient every ridge towards the highest peak of its part (breadth-first from it)
    adj: list[list[tuple[int, int]]] = [[] for _ in range(n)]
    for x, y, z in zip(a, b, s):
        adj[x].append((y, z))
        adj[y].append((x, z))
    parent = np.full(n, -1, np.int64)
    via = np.full(n, -1, np.int64)
    seen = np.zeros(n, bool)
    z = tree.peaks["elevation"].to_numpy(float)
    for root in np.lexsort((np.arange(n), -z)):
        if seen[root]:
            continue
        seen[root] = True
        queue = [int(root)]
        while queue:
            u = queue.pop()
            for v, sid in adj[u]:
                if not seen[v]:
                    seen[v], parent[v], via[v] = True, u, sid
                    queue.append(v)
    px, py = tree.peaks["x"].to_numpy(float).astype(np.int64), tree.peaks["y"].to_numpy(float).astype(np.int64)
    sx, sy = tree.saddles["x"].to_numpy(float).astype(np.int64), tree.saddles["y"].to_numpy(float).astype(np.int64)
    sz = tree.saddles["elevation"].to_numpy(float)
    lines = ["# Prominence divide tree written by orokit\n", cs + "\n"]
    lines += [f"P,{i + 1},{px[i]},{py[i]},{z[i]:.2f}\n" for i in range(n)]
    lines += [f"S,{j + 1},{'p' if j in key else 'b'},{sx[j]},{sy[j]},{sz[j]:.2f}\n" for j in range(tree.n_saddles)]
    lines.append("N,0,-1,-1\n")
    lines += [f"N,{i + 1},{parent[i] + 1 if parent[i] >= 0 else -1},{via[i] + 1 if via[i] >= 0 else -1}\n"
              for i in range(n)]
    write_text_atomic(Path(path), "".join(lines))
