"""Editing operations on Divide Trees that keep them valid.

Every operation returns a new :class:`DivideTree` (inputs are never modified) that
passes :meth:`DivideTree.validate`; orometric columns (``prominence``, ``dominance``,
``key_saddle``, ``parent``) of the peaks table are recomputed when present, or always
with :func:`refresh_orometry`.

Conventions: a ridge that closes a cycle removes the lowest saddle of that cycle (the
Divide Tree is the maximum spanning tree of the ridge network); deleting a peak keeps
the bottleneck saddle between every pair of remaining peaks (:meth:`DivideTree.subset`);
deleting a ridge splits the tree into two trees (a forest, each with its own root).
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from orokit.errors import DivideTreeError
from orokit.topology.divide_tree import DivideTree

__all__ = [
    "refresh_orometry",
    "add_peak",
    "move_peak",
    "delete_peak",
    "move_saddle",
    "add_ridge",
    "delete_ridge",
    "paste_fragment",
]

_OROMETRY_COLUMNS = ("prominence", "dominance", "key_saddle", "island_parent")


def refresh_orometry(tree: DivideTree) -> DivideTree:
    """Tree with ``prominence``, ``dominance``, ``key_saddle`` and ``island_parent`` recomputed."""
    tree.validate()
    table = tree.prominence_table()
    peaks = tree.peaks.copy()
    z = peaks["elevation"].to_numpy(float)
    peaks["prominence"] = table["prominence"].to_numpy()
    with np.errstate(divide="ignore", invalid="ignore"):
        peaks["dominance"] = np.where(z > 0, peaks["prominence"].to_numpy() / z, np.nan)
    peaks["key_saddle"] = table["key_saddle"].to_numpy()
    peaks["island_parent"] = table["island_parent"].to_numpy()
    return DivideTree(peaks, tree.saddles, tree.edges, tree.crs, dict(tree.attrs))


def _finish(tree: DivideTree) -> DivideTree:
    tree.validate()
    if any(c in tree.peaks.columns for c in _OROMETRY_COLUMNS):
        return refresh_orometry(tree)
    return tree


def _check_peak(tree: DivideTree, peak: int) -> int:
    if not 0 <= int(peak) < tree.n_peaks:
        raise DivideTreeError(f"peak id {peak} is out of range [0, {tree.n_peaks})")
    return int(peak)


def _check_ridge(tree: DivideTree, ridge: int) -> int:
    if not 0 <= int(ridge) < len(tree.edges):
        raise DivideTreeError(f"ridge id {ridge} is out of range [0, {len(tree.edges)})")
    return int(ridge)


def add_peak(
    tree: DivideTree,
    x: float,
    y: float,
    elevation: float,
    *,
    connect_to: int | None = None,
    saddle: tuple[float, float, float] | None = None,
) -> DivideTree:
    """Add a peak joined by a new ridge to ``connect_to`` (default: the nearest peak).

    ``saddle`` is (x, y, elevation); default: the ridge midpoint at
    ``min(elevation, h(connect_to))``. Raises DivideTreeError if the saddle would be
    above either peak. The new peak gets the last id.
    """
    if not np.isfinite([x, y, elevation]).all():
        raise DivideTreeError(f"peak position and elevation must be finite, got {(x, y, elevation)}")
    n = tree.n_peaks
    peaks = pd.concat([tree.peaks, pd.DataFrame({"x": [float(x)], "y": [float(y)], "elevation": [float(elevation)]})],
                      ignore_index=True)
    if n == 0:
        return _finish(DivideTree(peaks, tree.saddles, tree.edges, tree.crs, dict(tree.attrs)))
    if connect_to is None:
        d = np.hypot(tree.peaks["x"].to_numpy(float) - x, tree.peaks["y"].to_numpy(float) - y)
        connect_to = int(np.argmin(d))
    other = _check_peak(tree, connect_to)
    ox, oy, oz = (float(tree.peaks[c].iloc[other]) for c in ("x", "y", "elevation"))
    if saddle is None:
        saddle = ((x + ox) / 2, (y + oy) / 2, min(float(elevation), oz))
    if saddle[2] > min(float(elevation), oz):
        raise DivideTreeError(f"saddle elevation {saddle[2]:.1f} m is above a peak of its ridge "
                              f"({float(elevation):.1f} m, {oz:.1f} m)")
    saddles = pd.concat([tree.saddles, pd.DataFrame({"x": [saddle[0]], "y": [saddle[1]], "elevation": [saddle[2]]})],
                        ignore_index=True)
    edges = pd.concat([tree.edges, pd.DataFrame({"peak_a": [n], "peak_b": [other], "saddle": [tree.n_saddles]})],
                      ignore_index=True)
    return _finish(DivideTree(peaks, saddles, edges, tree.crs, dict(tree.attrs)))


def move_peak(
    tree: DivideTree,
    peak: int,
    x: float | None = None,
    y: float | None = None,
    elevation: float | None = None,
    *,
    lower_saddles: bool = True,
) -> DivideTree:
    """Move a peak and/or change its elevation.

    Lowering a peak below one of its ridge saddles lowers those saddles to the new
    elevation when ``lower_saddles`` (default), else raises DivideTreeError.
    """
    p = _check_peak(tree, peak)
    peaks = tree.peaks.copy()
    saddles = tree.saddles.copy()
    if x is not None:
        peaks.loc[p, "x"] = float(x)
    if y is not None:
        peaks.loc[p, "y"] = float(y)
    if elevation is not None:
        peaks.loc[p, "elevation"] = float(elevation)
        e = tree.edges
        mine = e["saddle"][(e["peak_a"] == p) | (e["peak_b"] == p)].to_numpy()
        too_high = mine[saddles["elevation"].to_numpy(float)[mine] > float(elevation)]
        if too_high.size and not lower_saddles:
            raise DivideTreeError(f"new elevation {elevation} m is below saddles {too_high.tolist()} of the peak; "
                                  "pass lower_saddles=True to lower them")
        saddles.loc[too_high, "elevation"] = float(elevation)
    return _finish(DivideTree(peaks, saddles, tree.edges, tree.crs, dict(tree.attrs)))


def delete_peak(tree: DivideTree, peak: int) -> DivideTree:
    """Remove a peak; its neighbours are rewired through their highest saddles.

    The bottleneck (highest) saddle between any two remaining peaks is unchanged,
    so every other peak keeps its prominence unless the deleted peak was its parent.
    """
    p = _check_peak(tree, peak)
    keep = np.ones(tree.n_peaks, bool)
    keep[p] = False
    return _finish(tree.subset(keep))


def move_saddle(tree: DivideTree, saddle: int, x: float | None = None, y: float | None = None,
                elevation: float | None = None) -> DivideTree:
    """Move a saddle and/or change its elevation (must stay at or below both peaks)."""
    if not 0 <= int(saddle) < tree.n_saddles:
        raise DivideTreeError(f"saddle id {saddle} is out of range [0, {tree.n_saddles})")
    s = int(saddle)
    saddles = tree.saddles.copy()
    if x is not None:
        saddles.loc[s, "x"] = float(x)
    if y is not None:
        saddles.loc[s, "y"] = float(y)
    if elevation is not None:
        e = tree.edges[tree.edges["saddle"] == s]
        if len(e):
            pz = tree.peaks["elevation"].to_numpy(float)
            top = min(pz[int(e["peak_a"].iloc[0])], pz[int(e["peak_b"].iloc[0])])
            if float(elevation) > top:
                raise DivideTreeError(f"saddle {s} cannot rise to {elevation} m: its ridge peaks allow at most "
                                      f"{top:.1f} m")
        saddles.loc[s, "elevation"] = float(elevation)
    return _finish(DivideTree(tree.peaks, saddles, tree.edges, tree.crs, dict(tree.attrs)))


def delete_ridge(tree: DivideTree, ridge: int) -> DivideTree:
    """Remove a ridge and its saddle: the tree splits in two (each part keeps a root)."""
    r = _check_ridge(tree, ridge)
    s = int(tree.edges["saddle"].iloc[r])
    edges = tree.edges.drop(index=tree.edges.index[r]).reset_index(drop=True)
    saddles = tree.saddles.drop(index=tree.saddles.index[s]).reset_index(drop=True)
    edges["saddle"] = np.where(edges["saddle"].to_numpy() > s, edges["saddle"].to_numpy() - 1, edges["saddle"].to_numpy())
    return _finish(DivideTree(tree.peaks, saddles, edges, tree.crs, dict(tree.attrs)))


def add_ridge(tree: DivideTree, peak_a: int, peak_b: int, saddle: tuple[float, float, float]) -> DivideTree:
    """Join two peaks by a ridge through ``saddle`` = (x, y, elevation).

    When both peaks are already connected the new ridge closes a cycle, and the
    lowest saddle of that cycle is removed (possibly the new one): the result is the
    maximum spanning tree of the ridges, as a Divide Tree must be.
    """
    a, b = _check_peak(tree, peak_a), _check_peak(tree, peak_b)
    if a == b:
        raise DivideTreeError(f"a ridge needs two different peaks, got {a} twice")
    pz = tree.peaks["elevation"].to_numpy(float)
    if saddle[2] > min(pz[a], pz[b]):
        raise DivideTreeError(f"saddle elevation {saddle[2]:.1f} m is above a peak of the ridge "
                              f"({pz[a]:.1f} m, {pz[b]:.1f} m)")
    path = _path_edges(tree, a, b)
    new_id = tree.n_saddles
    saddles = pd.concat([tree.saddles, pd.DataFrame({"x": [saddle[0]], "y": [saddle[1]], "elevation": [saddle[2]]})],
                        ignore_index=True)
    edges = pd.concat([tree.edges, pd.DataFrame({"peak_a": [a], "peak_b": [b], "saddle": [new_id]})],
                      ignore_index=True)
    out = DivideTree(tree.peaks, saddles, edges, tree.crs, dict(tree.attrs))
    if path is not None:
        cycle = np.append(path, len(edges) - 1)
        sz = saddles["elevation"].to_numpy(float)[edges["saddle"].to_numpy()[cycle]]
        # lowest saddle of the cycle; ties: the newest (highest saddle id) goes
        ids = edges["saddle"].to_numpy()[cycle]
        drop = cycle[np.lexsort((-ids, sz))[0]]
        out = delete_ridge(out, int(drop))
        return out
    return _finish(out)


def _path_edges(tree: DivideTree, a: int, b: int) -> np.ndarray | None:
    """Ridge ids on the tree path from peak a to peak b (None if not connected)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import breadth_first_order

    e = tree.edges
    n = tree.n_peaks
    if not len(e):
        return None
    ea, eb = e["peak_a"].to_numpy(), e["peak_b"].to_numpy()
    rid = np.arange(len(e))
    g = coo_matrix((np.ones(2 * len(e)), (np.concatenate([ea, eb]), np.concatenate([eb, ea]))), shape=(n, n)).tocsr()
    _, pred = breadth_first_order(g, a, directed=False, return_predecessors=True)
    if b != a and pred[b] < 0:
        return None
    lookup = {}
    for i, (u, v) in enumerate(zip(ea.tolist(), eb.tolist())):
        lookup[(u, v)] = lookup[(v, u)] = rid[i]
    out = []
    cur = b
    while cur != a:
        prev = int(pred[cur])
        out.append(lookup[(prev, cur)])
        cur = prev
    return np.asarray(out, np.int64)


def paste_fragment(tree: DivideTree, fragment: DivideTree, *, offset: tuple[float, float] = (0.0, 0.0),
                   connect_saddle_drop_m: float = 0.0) -> DivideTree:
    """Insert a Divide Tree fragment (shifted by ``offset``) into ``tree``.

    Peaks of ``tree`` within the fragment's (shifted) bounding box are deleted; the
    fragment is then joined to the rest by one ridge between its highest peak and
    the nearest remaining peak, with the saddle at ``min(h) - connect_saddle_drop_m``.
    To synthesize the rest *around* a fragment instead, pass it to
    :func:`orokit.synthesis.tree.synthesize_divide_tree` (``fragment=``).
    """
    fragment.validate()
    fp = fragment.peaks[["x", "y", "elevation"]].astype(float).copy()
    fp["x"] += offset[0]
    fp["y"] += offset[1]
    fs = fragment.saddles[["x", "y", "elevation"]].astype(float).copy()
    fs["x"] += offset[0]
    fs["y"] += offset[1]
    x0, x1, y0, y1 = fp["x"].min(), fp["x"].max(), fp["y"].min(), fp["y"].max()
    px, py = tree.peaks["x"].to_numpy(float), tree.peaks["y"].to_numpy(float)
    inside = (px >= x0) & (px <= x1) & (py >= y0) & (py <= y1)
    base = tree.subset(~inside) if inside.any() else tree
    n0, s0 = base.n_peaks, base.n_saddles
    cols = ["x", "y", "elevation"]
    peaks = pd.concat([base.peaks[cols], fp], ignore_index=True)
    saddles = pd.concat([base.saddles[cols], fs], ignore_index=True)
    fe = fragment.edges[["peak_a", "peak_b", "saddle"]].to_numpy(np.int64) + np.array([n0, n0, s0])
    edges = pd.concat([base.edges[["peak_a", "peak_b", "saddle"]], pd.DataFrame(fe, columns=["peak_a", "peak_b", "saddle"])],
                      ignore_index=True)
    out = DivideTree(peaks, saddles, edges, tree.crs, dict(tree.attrs))
    if n0 and len(fp):
        top = n0 + int(np.argmax(fp["elevation"].to_numpy()))
        d = np.hypot(px[~inside] - peaks["x"].iloc[top], py[~inside] - peaks["y"].iloc[top])
        near = int(np.argmin(d))
        zmin = min(float(peaks["elevation"].iloc[top]), float(peaks["elevation"].iloc[near]))
        sad = ((peaks["x"].iloc[top] + peaks["x"].iloc[near]) / 2, (peaks["y"].iloc[top] + peaks["y"].iloc[near]) / 2,
               max(zmin - connect_saddle_drop_m, 0.0))
        return add_ridge(out, top, near, sad)
    return _finish(out)
