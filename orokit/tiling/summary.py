"""Chunk summaries of the saddle graph and their exact merge.

A :class:`ChunkSummary` describes a rectangle of the raster by a small tree whose
nodes are candidate peaks and the cells on the rectangle's sides that face other
chunks, and whose edges carry bottleneck (highest-pass) saddles. It keeps the exact
bottleneck saddle between any two of its nodes, so summaries of neighbouring
rectangles merge exactly: add "seam" edges between adjacent side cells (weight =
the lower cell), take the maximum spanning tree, and contract the nodes that are no
longer needed (DESIGN.md §2 step 5).

Basins follow the raster's own steepest ascent (the halo is read): a chain that
leaves the chunk ends at an *exit* node, tied to the cell it climbs to in the next
chunk by an edge of infinite height, and every side cell is tied to its basin the
same way. So a node stands for (a piece of) one basin of the whole raster, the merged
graph is the in-memory engine's basin graph, and removed peaks are absorbed into the
same kept peaks as in memory (same pruned Divide Tree, hence the same line and
prominence parents).

Nodes whose prominence *within the rectangle* is below the threshold are contracted
early: terrain outside can only add paths and higher ground, so a chunk-local
prominence is an upper bound of the true one.

Everything is in the global total order of the raster (elevation, then flat index),
so the merged result equals the in-memory engine's.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit

from orokit.tiling.memory import release_free_heap
from orokit.topology import _kernels as _k
from orokit.topology.engine import Orometry, finalize_graph, saddle_order

__all__ = ["ChunkSummary", "chunk_summary", "merge_summaries", "finalize_summary", "settled_peaks"]

_FIELDS = ("key", "z", "ismax", "bmax", "nmin", "nexit", "ea", "eb", "ez", "ekey")
_NO_EDGES = np.empty(0, np.int64)
#: a consuming merge hands the heap's free pages back after each merged field of this size or more
#: (:func:`merge_summaries`): the top merges' parts would otherwise stay resident beside the merged summary
_TRIM_BYTES = 8 << 20
_OFFSETS = ((-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1))


@dataclass
class ChunkSummary:
    """Saddle tree of a raster rectangle ``rows [r0, r1) x cols [c0, c1)``."""

    region: tuple[int, int, int, int]
    shape: tuple[int, int]       # whole raster (H, W)
    key: np.ndarray              # global flat cell of each node
    z: np.ndarray                # elevation of each node
    ismax: np.ndarray            # node is a maximum (candidate peak)
    bmax: np.ndarray             # highest border ("unknown outside") value reachable
    nmin: np.ndarray             # lowest elevation of the node's absorbed area
    nexit: np.ndarray            # exit node: global cell its ascent climbs to next (else -1)
    ea: np.ndarray
    eb: np.ndarray
    ez: np.ndarray               # saddle elevation
    ekey: np.ndarray             # saddle cell (global flat index)
    n_maxima: int = 0            # global maxima counted inside the rectangle
    consumed: bool = False       # its arrays were handed to a merge (``consume=True``) and freed

    @property
    def n_nodes(self) -> int:
        return int(self.key.size)

    def release(self) -> None:
        """Free the arrays (the owner passed them on): a later use raises instead of reading an empty tree."""
        for f in _FIELDS:
            setattr(self, f, _NO_EDGES)
        self.consumed = True

    def nbytes(self) -> int:
        return sum(getattr(self, f).nbytes for f in _FIELDS)

    def to_npz(self) -> dict:
        out = {f: getattr(self, f) for f in _FIELDS}
        out["meta"] = np.array([*self.region, *self.shape, self.n_maxima], dtype=np.int64)
        return out

    @classmethod
    def from_npz(cls, data) -> "ChunkSummary":
        m = data["meta"]
        arrays = {f: data[f] for f in _FIELDS}
        return cls((int(m[0]), int(m[1]), int(m[2]), int(m[3])), (int(m[4]), int(m[5])), **arrays, n_maxima=int(m[6]))


def _side_mask(keys: np.ndarray, region, shape) -> np.ndarray:
    """Cells on a side of ``region`` that faces other cells of the raster."""
    r0, r1, c0, c1 = region
    H, W = shape
    r, c = keys // W, keys % W
    return (
        ((r == r0) & (r0 > 0)) | ((r == r1 - 1) & (r1 < H)) | ((c == c0) & (c0 > 0)) | ((c == c1 - 1) & (c1 < W))
    )


def _reduce(s: ChunkSummary, min_prominence_m: float, needed: np.ndarray) -> ChunkSummary:
    """Maximum spanning tree of the summary graph, then contract unneeded nodes.

    Kept: ``needed`` nodes (side cells) and maxima that are roots or whose
    prominence within the rectangle reaches the threshold (and is > 0).
    ``s`` is a temporary of the caller and is consumed: its edges are replaced by their
    sorted copies, then dropped, so the unsorted ones are freed during the sweep (the
    top merges hold several hundred bytes per node at their peak).
    """
    n = s.n_nodes
    if n == 0:
        return s
    order = np.lexsort((s.ekey, -s.ez))
    # one edge array at a time: each unsorted one is freed as its sorted copy replaces it
    s.ea = s.ea[order]
    s.eb = s.eb[order]
    s.ez = s.ez[order]
    s.ekey = s.ekey[order]
    del order
    ea, eb, ez, ekey = s.ea, s.eb, s.ez, s.ekey
    _, key_edge, _, _ = _k.kruskal_sweep_like(s.z, s.key, ea, eb, ez, ekey, s.bmax, _k.index_like(n, ea.size))
    nonroot = np.flatnonzero(key_edge >= 0)
    prom = np.full(n, np.inf)
    prom[nonroot] = s.z[nonroot] - ez[key_edge[nonroot]]
    keep = needed | (s.ismax & ((key_edge < 0) | ((prom >= min_prominence_m) & (prom > 0))))
    del nonroot, prom, key_edge
    # defer: where one saddle joins several kept parts, a removed part stays and every edge of
    # that saddle is kept, until the final prune (same choices as the in-memory engine)
    oa, ob, oe, nb, nm, keep = _k.prune_edges(n, ea, eb, ez, ekey, keep, s.bmax, s.nmin, s.z, s.key, True,
                                              _k.index_like(n, ea.size))
    del ea, eb, ez, ekey
    s.ea = s.eb = s.bmax = s.nmin = _NO_EDGES
    # edge ends in the narrowest index type (int32 below 2**31 nodes: 8 bytes per edge less held)
    new_id = np.full(n, -1, _k.index_like(n).dtype)
    kept = np.flatnonzero(keep)
    del keep
    new_id[kept] = np.arange(kept.size)
    # the reduced summary one array at a time, each source freed once taken (the top merges of a
    # 4 G-cell mosaic: ~6.5 M nodes)
    out: dict[str, Any] = {}
    for f, src in (("bmax", nb), ("nmin", nm)):
        out[f] = src[kept]
    del nb, nm
    for f in ("key", "z", "ismax", "nexit"):
        out[f] = getattr(s, f)[kept]
        setattr(s, f, _NO_EDGES)
    del kept
    out["ea"] = new_id[oa]
    del oa
    out["eb"] = new_id[ob]
    del ob, new_id
    out["ez"] = s.ez[oe]
    s.ez = _NO_EDGES
    out["ekey"] = s.ekey[oe]
    s.ekey = _NO_EDGES
    del oe
    return ChunkSummary(s.region, s.shape, **out, n_maxima=s.n_maxima)


def _frame(h: int, w: int) -> np.ndarray:
    """Flat indices of the cells on the sides of an h x w block, increasing, each once."""
    rows = np.arange(1, h - 1)
    inner = np.stack([rows * w, rows * w + w - 1], axis=1).ravel() if w > 1 else rows * w
    last = np.arange((h - 1) * w, h * w) if h > 1 else np.empty(0, np.int64)
    return np.concatenate([np.arange(w), inner, last]).astype(np.int64)


def chunk_summary(zh: np.ndarray, row0: int, col0: int, shape: tuple[int, int],
                  min_prominence_m: float) -> ChunkSummary:
    """Summary of one chunk given with a one-cell halo (NaN outside the raster).

    Parameters
    ----------
    zh : (h + 2, w + 2) array: the chunk and one cell of its neighbours all round.
    row0, col0 : global position of the chunk's first cell; shape : raster (H, W).
    """
    H, W = shape
    zh = np.ascontiguousarray(zh)
    core = np.ascontiguousarray(zh[1:-1, 1:-1])
    h, w = core.shape
    region = (row0, row0 + h, col0, col0 + w)
    ptr, exit_to, border = _k.steepest_ascent(zh)
    label, end_cell = _k.label_basins(ptr)
    del ptr
    out = exit_to[end_cell]  # chain ends: maxima of the raster, or exits whose ascent goes on next door
    del exit_to
    npk = end_cell.size
    empty_i = np.empty(0, np.int64)
    if npk == 0:
        return ChunkSummary(region, (H, W), empty_i, np.empty(0), np.empty(0, bool), np.empty(0), np.empty(0),
                            empty_i, empty_i, empty_i, np.empty(0, zh.dtype), empty_i, 0)
    zf = core.ravel()
    bz = _k.basin_border_max(core, label, border, npk)
    nmin = _k.basin_min(core, label, npk)
    ea, eb, ec = _k.basin_passes(core, label, npk)

    def glob(i):
        return (row0 + i // w) * W + col0 + i % w

    is_exit = out >= 0
    nexit = np.where(is_exit, (row0 - 1 + out // (w + 2)) * W + col0 - 1 + out % (w + 2), -1)
    # side cells that are not chain ends become extra nodes, tied to their basin
    side_cells = _frame(h, w)
    side_cells = side_cells[label[side_cells] >= 0]
    side_cells = side_cells[_side_mask(glob(side_cells), region, shape)]
    is_end = np.zeros(h * w, bool)
    is_end[end_cell] = True
    extra = side_cells[~is_end[side_cells]]
    ne = extra.size
    key = np.concatenate([glob(end_cell), glob(extra)])
    z = np.concatenate([zf[end_cell], zf[extra]]).astype(np.float64)
    ismax = np.concatenate([~is_exit, np.zeros(ne, bool)])
    bmax = np.concatenate([bz, np.full(ne, -np.inf)])
    nm = np.concatenate([nmin, zf[extra].astype(np.float64)])
    nx = np.concatenate([nexit, np.full(ne, -1, np.int64)])
    xa = np.concatenate([ea, npk + np.arange(ne)])
    xb = np.concatenate([eb, label[extra]])
    # a side cell is part of its basin: an edge above every saddle; its key (-1 - cell) is
    # no saddle cell, so no sweep takes it for the same event as a real saddle
    xk = np.concatenate([glob(ec), -1 - glob(extra)])
    # saddle values in the raster's type (float32 ones are exact: 4 bytes per edge less held); the
    # kernels compare them with the nodes' float64 values and subtract in float64, so nothing changes
    xz = np.concatenate([zf[ec], np.full(ne, np.inf, zf.dtype)])
    s = ChunkSummary(region, (H, W), key, z, ismax, bmax, nm, nx, xa, xb, xz, xk, int((~is_exit).sum()))
    return _reduce(s, min_prominence_m, _side_mask(key, region, shape))


def merge_summaries(a: ChunkSummary, b: ChunkSummary, min_prominence_m: float, *,
                    consume: bool = False, reduce: bool = True) -> ChunkSummary:
    """Exact merge of the summaries of two rectangles that together form a rectangle.

    ``consume``: ``a`` and ``b`` are released (:meth:`ChunkSummary.release`) once their
    nodes and edges are in the merged graph, so the merge's sort and sweep run without
    them (at the top merges of a 4 G-cell mosaic the two inputs are ~0.5 GB).
    ``reduce=False``: the merged graph as it is, not contracted (its bottlenecks are exact):
    for the root, whose :func:`finalize_summary` sorts, sweeps and prunes it anyway, so the
    root's nodes are not swept and pruned twice (the top merge of a 4 G-cell mosaic: ~6.5 M).
    """
    if a.consumed or b.consumed:
        from orokit.errors import TilingError

        raise TilingError("a chunk summary was already merged (a merge task ran twice?): rerun the analysis")
    H, W = a.shape
    region = (min(a.region[0], b.region[0]), max(a.region[1], b.region[1]),
              min(a.region[2], b.region[2]), max(a.region[3], b.region[3]))
    na = a.n_nodes
    # seam edges between 8-adjacent side cells of a and b
    order_b = np.argsort(b.key)
    kb = b.key[order_b]
    sa = np.flatnonzero(_side_mask(a.key, a.region, a.shape))
    ra, ca = a.key[sa] // W, a.key[sa] % W
    sea_parts: list[np.ndarray] = []
    seb_parts: list[np.ndarray] = []
    for dr, dc in _OFFSETS:
        nr, nc = ra + dr, ca + dc
        ok = (nr >= b.region[0]) & (nr < b.region[1]) & (nc >= b.region[2]) & (nc < b.region[3])
        nk = nr * W + nc
        pos = np.searchsorted(kb, nk)
        pos = np.minimum(pos, max(kb.size - 1, 0))
        hit = ok & (kb.size > 0) & (kb[pos] == nk) if kb.size else np.zeros_like(ok)
        sea_parts.append(sa[hit])
        seb_parts.append(order_b[pos[hit]])
    sea = np.concatenate(sea_parts) if sea_parts else np.empty(0, np.int64)
    seb = np.concatenate(seb_parts) if seb_parts else np.empty(0, np.int64)
    za, zb = a.z[sea], b.z[seb]
    ka, kbb = a.key[sea], b.key[seb]
    a_lower = (za < zb) | ((za == zb) & (ka > kbb))
    # an exit and the cell its ascent climbs to belong to one basin: an edge above every saddle
    same_basin = (a.nexit[sea] == kbb) | (b.nexit[seb] == ka)
    sz = np.where(same_basin, np.inf, np.where(a_lower, za, zb))
    sk = np.where(a_lower, ka, kbb)
    sk = np.where(same_basin, -1 - sk, sk)
    del za, zb, ka, kbb, a_lower, same_basin, order_b, kb, sa, ra, ca
    # edge ends in the narrowest index type of the merged graph, saddle values in the parts' type (a
    # seam's value is a node's, a raster value, so exact in the raster's float32)
    index = _k.index_like(na + b.n_nodes, a.ea.size + b.ea.size + sea.size).dtype
    types = {"ea": index, "eb": index, "ez": np.result_type(a.ez, b.ez)}
    seam = {"ea": sea, "eb": seb + na, "ez": sz, "ekey": sk}
    del sea, seb, sz, sk
    n_maxima = a.n_maxima + b.n_maxima
    merged: dict[str, Any] = {}
    for f in _FIELDS:  # one field at a time; consumed inputs free each field once it is joined
        parts = [getattr(a, f), np.add(getattr(b, f), na, dtype=index) if f in ("ea", "eb") else getattr(b, f)]
        if f in seam:
            parts.append(seam.pop(f))
        merged[f] = np.concatenate(parts, dtype=types.get(f), casting="same_kind")
        del parts
        if consume:
            setattr(a, f, _NO_EDGES)
            setattr(b, f, _NO_EDGES)
            if merged[f].nbytes >= _TRIM_BYTES:
                # the parts' arrays (under the mmap threshold) leave holes in the heap that the merged ones (over
                # it, or larger than any hole) do not reuse: handed back now, or the root merge holds both
                release_free_heap()
    if consume:
        a.release()
        b.release()
    s = ChunkSummary(region, a.shape, **merged, n_maxima=n_maxima)
    del merged
    if not reduce:
        return s
    return _reduce(s, min_prominence_m, _side_mask(s.key, region, s.shape))


def finalize_summary(s: ChunkSummary, *, min_prominence_m: float, outside: str,
                     consume: bool = False, store: Any = None) -> Orometry:
    """Peaks and Divide Tree of the whole raster from its root summary.

    ``consume``: ``s`` is released (:meth:`ChunkSummary.release`) as its arrays are handed to
    :func:`~orokit.topology.engine.finalize_graph`, which lets each go once used (at a 4 G-cell
    mosaic's root, ~6.5 M nodes, they are freed during the finalize instead of after it).
    ``store``: a column store where the finalize puts the result's columns the isolation search
    does not read (:func:`~orokit.topology.engine.finalize_graph`).
    """
    if s.n_nodes == 0:
        from orokit.errors import InputError

        raise InputError("the DEM has no valid cells (all nodata)")
    shape, n_maxima = s.shape, s.n_maxima
    arrays = {f: getattr(s, f) for f in ("key", "z", "bmax", "nmin", "ismax", "ea", "eb", "ez", "ekey")}
    if consume:
        s.release()
    if arrays["ez"].dtype == np.float32:
        # node values are raster values too (or infinite): float32 when every one is exact in it (12 bytes
        # per node less through the sort and the sweep; finalize_graph widens them before any arithmetic)
        for f in ("z", "bmax", "nmin"):
            narrow = arrays[f].astype(np.float32)
            if np.array_equal(narrow, arrays[f], equal_nan=True):
                arrays[f] = narrow
            del narrow
    # the edges in the finalize's order once, here, one array at a time (with ``consume`` each unsorted
    # one is freed as its sorted copy replaces it), so finalize_graph neither sorts nor copies them
    order = saddle_order(arrays["ea"], arrays["eb"], arrays["ez"], arrays["ekey"])
    for f in ("ea", "eb", "ez", "ekey"):
        arrays[f] = arrays[f][order]
    del order
    # popped as the call is made: this frame keeps no reference while finalize_graph runs
    return finalize_graph(
        node_key=arrays.pop("key"), node_z=arrays.pop("z"), node_bmax=arrays.pop("bmax"),
        node_nmin=arrays.pop("nmin"), node_ismax=arrays.pop("ismax"), ea=arrays.pop("ea"), eb=arrays.pop("eb"),
        ez=arrays.pop("ez"), ekey=arrays.pop("ekey"), min_prominence_m=min_prominence_m, outside=outside,
        shape=shape, n_maxima=n_maxima, store=store, edges_sorted=True,
    )


@njit(cache=True, nogil=True)
def _root(uf, x):
    while uf[x] != x:
        uf[x] = uf[uf[x]]  # path halving
        x = uf[x]
    return x


@njit(cache=True, nogil=True)
def _side_above_key(n, ea, eb, ekey, side, key_edge):
    """Per node: a ``side`` node is in its component just before the event (saddle cell) of its
    key edge. Edges sorted as for :func:`~orokit.topology._kernels.kruskal_sweep`."""
    uf = np.arange(n)
    has = side.copy()
    order = np.argsort(key_edge)
    out = np.zeros(n, np.bool_)
    i = 0
    while i < n and key_edge[order[i]] < 0:
        i += 1
    m = ea.size
    e = 0
    while e < m:
        f = e + 1
        while f < m and ekey[f] == ekey[e]:
            f += 1
        while i < n and key_edge[order[i]] < f:  # nodes dying at this event: their component before it
            p = order[i]
            out[p] = has[_root(uf, p)]
            i += 1
        for g in range(e, f):
            ra = _root(uf, ea[g])
            rb = _root(uf, eb[g])
            if ra != rb:
                uf[rb] = ra
                has[ra] = has[ra] or has[rb]
        e = f
    return out


def settled_peaks(s: ChunkSummary, min_prominence_m: float) -> dict[str, np.ndarray]:
    """Candidate peaks of a summary that nothing outside its rectangle can change.

    A maximum p whose component above its key saddle (edges before the key edge's saddle
    cell in the total order) holds no side node of the rectangle is *settled*: a path from p
    that leaves the rectangle crosses a side cell, so it goes below the key saddle first, and
    terrain outside can neither raise the key saddle nor change its cell; its prominence and
    ``prominence_exact`` are final (its parent is not). This is the criterion of the streaming
    design in docs/scaling.md (not used by the engine yet).

    Returns arrays over the settled maxima: ``node`` (index in ``s``), ``cell``, ``key_saddle_cell``,
    ``key_saddle_z``, ``prominence``, ``touched`` (the border is reached above the key saddle:
    prominence not exact when the outside is unknown), and ``kept`` (prominence reaches
    ``min_prominence_m``: it is a peak of the final result).
    """
    n = s.n_nodes
    fields = ("node", "cell", "key_saddle_cell", "key_saddle_z", "prominence", "touched", "kept")
    if n == 0 or s.ea.size == 0:
        return {f: np.empty(0) for f in fields}
    order = np.lexsort((s.ekey, -s.ez))
    ea, eb, ez, ekey = s.ea[order], s.eb[order], s.ez[order], s.ekey[order]
    _, key_edge, _, touched = _k.kruskal_sweep(s.z, s.key, ea, eb, ez, ekey, s.bmax)
    side = _side_mask(s.key, s.region, s.shape)
    open_ = _side_above_key(n, ea, eb, ekey, side, key_edge)
    node = np.flatnonzero(s.ismax & (key_edge >= 0) & ~open_)
    ke = key_edge[node]
    prom = s.z[node] - ez[ke]
    return {"node": node, "cell": s.key[node], "key_saddle_cell": ekey[ke], "key_saddle_z": ez[ke],
            "prominence": prom, "touched": touched[node],
            "kept": (prom >= min_prominence_m) & (prom > 0)}
