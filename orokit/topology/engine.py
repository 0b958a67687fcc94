"""In-memory exact orometry engine (one raster held in memory).

Steps (DESIGN.md §2):

1. Steepest ascent: every cell points to its highest 8-neighbour in the total order
   (elevation, then raster order); chains end at the maxima of that order.
2. Basins: every cell belongs to the maximum its chain reaches.
3. Passes: for each pair of adjacent basins the highest pass is the highest of the
   lower cells of their adjacent cell pairs (hash-reduced in one sweep).

Steps 1-3 run by row strips (:func:`saddle_graph`): a strip's cells are labelled with
their chains' ends inside it (a maximum or an exit to the next strip), the exits are
resolved through the strips' first and last rows, so no label per raster cell is held.
4. One Kruskal sweep over the passes from high to low gives the maximum spanning tree
   of the basin graph (the full Divide Tree) and, by the elder rule, every maximum's
   key saddle, parent and prominence, plus the "touched the unknown outside" flag.
5. Maxima of prominence 0 are flat shelves or duplicate cells of a plateau: dropped;
   the tree is pruned at the threshold by bottleneck-preserving star contraction.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from orokit.errors import InputError
from orokit.topology import _kernels, _strip_kernels
from orokit.topology.divide_tree import DivideTree
from orokit.topology.tables import (
    PEAK_COLUMNS,
    CellPlaces,
    SADDLE_COLUMNS,
    AnalysisResult,
    TableBlocks,
    validate_peak_table,
    validate_saddle_table,
)

if TYPE_CHECKING:
    import pandas as pd


@dataclass
class Orometry:
    """Raw engine output on cell indices (before tables and isolation)."""

    shape: tuple[int, int]
    n_maxima: int
    peak_cell: np.ndarray        # flat cell of each kept peak (raster order)
    peak_z: np.ndarray
    prominence: np.ndarray
    key_saddle_cell: np.ndarray  # -1 for roots
    key_saddle_z: np.ndarray     # NaN for roots
    parent: np.ndarray           # index into kept peaks, -1 for roots
    prominence_exact: np.ndarray
    ridge_a: np.ndarray          # kept-peak indices of each ridge
    ridge_b: np.ndarray
    ridge_saddle_cell: np.ndarray
    ridge_saddle_z: np.ndarray

    @property
    def n_kept(self) -> int:
        return int(self.peak_cell.size)

    @property
    def peak_row(self) -> np.ndarray:
        return self.peak_cell // self.shape[1]

    @property
    def peak_col(self) -> np.ndarray:
        return self.peak_cell % self.shape[1]


def steepest_ascent_basins(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Basins of steepest ascent of a 2-D array in the engine's total order (NaN = nodata).

    Returns ``(label, max_cell)``: the basin (index into ``max_cell``, -1 for NaN cells)
    of every cell in raster order, and the flat cell of each basin's maximum. Ties break
    as in :func:`orometry` (elevation, then raster order; earlier = higher).
    """
    label = np.empty(z.size, np.int64)
    max_cell = _kernels.ascent_labels(np.ascontiguousarray(z), label)
    return label, max_cell


def _threads() -> int:
    import numba

    return int(numba.get_num_threads())


def orometry(z: np.ndarray, *, min_prominence_m: float, outside: str = "unknown") -> Orometry:
    """Exact peaks, prominences and pruned Divide Tree of a 2-D array (NaN = nodata).

    Uses every numba thread (``NUMBA_NUM_THREADS``); results do not depend on it.
    """
    return finalize_graph(**saddle_graph(z), min_prominence_m=min_prominence_m, outside=outside)


def _has_inf(z: np.ndarray) -> bool:
    """Whether ``z`` holds +-inf, from two reductions that skip NaN (no temporary of z's size: a bool
    per cell, 14 MiB at 15 M cells, stayed in the heap through the engine's peak).

    >>> _has_inf(np.array([1.0, np.nan])), _has_inf(np.array([np.nan, -np.inf]))
    (False, True)
    """
    return bool(z.size) and bool(np.isinf(np.fmax.reduce(z, axis=None)) or np.isinf(np.fmin.reduce(z, axis=None)))


#: cells per row strip of :func:`saddle_graph` (a strip's terminal per cell, 4 bytes, is held while it is worked)
STRIP_CELLS = 1 << 21


def strip_bounds(shape: tuple[int, int], strips: int | None = None) -> list[tuple[int, int]]:
    """The row strips ``(r0, r1)`` of :func:`saddle_graph`: ``strips`` of them (at most one per row), by
    default enough for :data:`STRIP_CELLS` cells each, at least two per numba thread and a multiple of
    the threads (strips of equal work end together: with 29 strips on two threads, the last ran alone).

    >>> strip_bounds((10, 4), 3)
    [(0, 3), (3, 6), (6, 10)]
    """
    H, W = shape
    if strips is None:
        threads = _threads()
        strips = max(2 * threads, -(-H * W // STRIP_CELLS))
        strips = -(-strips // threads) * threads
    k = max(1, min(int(strips), H))
    return [(t * H // k, (t + 1) * H // k) for t in range(k)]


def saddle_graph(z: np.ndarray, *, strips: int | None = None) -> dict[str, Any]:
    """Steps 1-3 of :func:`orometry`: the basins' saddle graph, as keyword arguments of :func:`finalize_graph`.

    Row strips (:func:`strip_bounds`), two at a time per numba thread, each labelled with the
    terminals of its chains (:mod:`orokit.topology._strip_kernels`): no label per raster cell is
    held, only a strip's (4 bytes per cell of a strip). The chains that leave a strip (exits)
    are resolved through the neighbouring strips' first and last rows, the pairs across each
    strip's last row made from those rows; every basin pair keeps its highest pass. The graph
    does not depend on ``strips``.
    """
    if z.ndim != 2 or z.size == 0:
        raise InputError(f"the DEM must be a non-empty 2-D array; got shape {z.shape}")
    if _has_inf(z):
        raise InputError("the DEM contains infinite values; mark nodata as NaN")
    z = np.ascontiguousarray(z)
    H, W = z.shape
    bounds = strip_bounds(z.shape, strips)
    big = max(r1 - r0 for r0, r1 in bounds) * W + 2 * W + 2 >= 2**31
    ltype = np.int64 if big or z.size >= 2**31 - 2 else np.int32

    def strip(b: tuple[int, int]) -> tuple[Any, ...]:
        return _strip(z, b[0], b[1], ltype)

    if len(bounds) == 1:
        parts = [strip(bounds[0])]
    else:
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(min(_threads(), len(bounds))) as pool:
            parts = list(pool.map(strip, bounds))
    n_max, node_key, bmax, nmin, ea, eb, ec = _join_strips(z, bounds, parts)
    del parts
    if n_max == 0:
        raise InputError("the DEM has no valid cells (all nodata)")
    zf = z.ravel()
    return {
        "node_key": node_key,
        "node_z": zf[node_key].astype(np.float64),
        "node_bmax": bmax,
        "node_nmin": nmin,
        "node_ismax": np.ones(n_max, bool),
        "ea": ea,
        "eb": eb,
        "ez": zf[ec].astype(np.float64),
        "ekey": ec,
        "shape": z.shape,
        "n_maxima": n_max,
    }


def _strip(z: np.ndarray, r0: int, r1: int, ltype: type) -> tuple[Any, ...]:
    """One row strip of :func:`saddle_graph`: ``(m, max_cells, bmax, nmin, ea, eb, ec, first_row, last_row)``."""
    W = z.shape[1]
    lab = np.empty((r1 - r0) * W, ltype)
    m, cells = _strip_kernels.strip_ascent(z, r0, r1, lab)
    graph = _strip_kernels.strip_graph(z, lab, m + 2 * W, r0, r1)
    return (int(m), cells, *graph, lab[:W].astype(np.int64), lab[-W:].astype(np.int64))


def load_strip_kernels() -> None:
    """Load the kernels of :func:`saddle_graph`'s strips (numba's cache) for float32 rasters, on a tiny one:
    what the strips need before they can start (the join's and the finalize's kernels load with
    :func:`orometry`)."""
    _strip(np.zeros((2, 2), np.float32), 0, 2, np.int32)


def _join_strips(z: np.ndarray, bounds: list[tuple[int, int]], parts: list[tuple[Any, ...]]) -> tuple[Any, ...]:
    """The basins' graph from the strips' terminals: ``(n_max, max_cell, bmax, nmin, ea, eb, ec)``.

    ``parts[s]``: ``(m, max_cells, bmax, nmin, ea, eb, ec, first_row, last_row)`` of strip ``s``
    over its terminal ids. Each exit goes to the terminal of its target cell in the next strip
    up or down (that strip's last or first row), until a maximum (chains rise: no cycle).
    """
    H, W = z.shape
    sizes = np.array([p[0] + 2 * W for p in parts], np.int64)
    offs = np.concatenate([[0], np.cumsum(sizes)])
    total = int(offs[-1])
    nowhere = total  # the target of an exit no chain takes out of the raster or into NaN
    nxt = np.arange(total + 1, dtype=np.int64)
    is_max = np.zeros(total + 1, bool)
    for s, p in enumerate(parts):
        m, o = p[0], int(offs[s])
        is_max[o:o + m] = True
        for t, other in ((o + m, s - 1), (o + m + W, s + 1)):
            if 0 <= other < len(parts):
                row = parts[other][8] if other < s else parts[other][7]  # its last row, or its first
                nxt[t:t + W] = np.where(row >= 0, offs[other] + row, nowhere)
            else:
                nxt[t:t + W] = nowhere
    while True:  # pointer jumping to each chain's maximum
        jumped = nxt[nxt]
        if np.array_equal(jumped, nxt):
            break
        nxt = jumped
    n_max = int(is_max.sum())
    basin_of = np.full(total + 1, -1, np.int64)
    basin_of[np.flatnonzero(is_max)] = np.arange(n_max)
    term = basin_of[nxt]  # the basin of every terminal (-1: none)
    del nxt, basin_of, is_max
    node_key = np.concatenate([p[1] for p in parts]).astype(np.int64)
    bmax = np.full(n_max, -np.inf)
    nmin = np.full(n_max, np.inf)
    # a basin pair is found twice only through an exit or across a seam (a strip's own maxima are its
    # own, each pair of them once): the basins that exits and seam rows reach are the candidates
    touched = np.zeros(n_max + 1, bool)  # [-1]: none
    pieces_a, pieces_b, pieces_c = [], [], []
    zf = z.ravel()
    for s, p in enumerate(parts):
        o, m = int(offs[s]), p[0]
        tb = term[o:o + sizes[s]]
        _strip_kernels.terminal_extremes(bmax, nmin, tb, p[2], p[3])
        touched[tb[m:]] = True
        pieces_a.append(tb[p[4]])
        pieces_b.append(tb[p[5]])
        pieces_c.append(p[6])
        if s + 1 < len(parts):  # the pairs across this strip's last row and the next strip's first
            r = bounds[s][1]
            up = np.where(p[8] >= 0, term[o + np.maximum(p[8], 0)], -1)
            nx = parts[s + 1][7]
            down = np.where(nx >= 0, term[int(offs[s + 1]) + np.maximum(nx, 0)], -1)
            touched[up] = touched[down] = True
            for dc in (-1, 0, 1):
                c = np.arange(max(0, -dc), min(W, W - dc))
                la, lb = up[c], down[c + dc]
                ok = (la >= 0) & (lb >= 0) & (la != lb)
                c, la, lb = c[ok], la[ok], lb[ok]
                i = (r - 1) * W + c
                j = r * W + c + dc
                zi, zj = zf[i], zf[j]
                i_above = (zi > zj) | ((zi == zj) & (i < j))
                pieces_a.append(la)
                pieces_b.append(lb)
                pieces_c.append(np.where(i_above, j, i).astype(np.int64))  # the pass: the lower cell
    a = np.concatenate(pieces_a)
    b = np.concatenate(pieces_b)
    c = np.concatenate(pieces_c).astype(np.int64, copy=False)
    del pieces_a, pieces_b, pieces_c
    touched[-1] = False
    # both ends resolved to one basin: not a pass; per basin pair among the candidates, the highest pass
    lo, hi, c = _strip_kernels.basin_pairs(a, b, c, zf, touched, n_max)  # a, b, c overwritten
    del a, b
    return n_max, node_key, bmax, nmin, lo, hi, c


def finalize_graph(
    *,
    node_key: np.ndarray,
    node_z: np.ndarray,
    node_bmax: np.ndarray,
    node_nmin: np.ndarray,
    node_ismax: np.ndarray,
    ea: np.ndarray,
    eb: np.ndarray,
    ez: np.ndarray,
    ekey: np.ndarray,
    min_prominence_m: float,
    outside: str,
    shape: tuple[int, int],
    n_maxima: int,
    store: Any = None,
    edges_sorted: bool = False,
) -> Orometry:
    """Peaks and pruned Divide Tree from a saddle graph whose bottlenecks are exact.

    Nodes are candidate maxima (``node_ismax``) and possibly other cells; edges carry
    the saddle cell (``ekey``, flat index) and its elevation. Used by the in-memory
    engine (nodes = basins) and by the tiled engine (nodes = merged tile summaries).
    Each array is let go once used (a caller that holds no other reference, as the tiled
    engine's finalize, frees it then: ~100 bytes per node of a 6.5 M-node root).
    ``edges_sorted``: the edges are in :func:`saddle_order` already (not sorted again).
    ``store`` (a column store, see :func:`spill_orometry`): the :data:`SPILLED_OROMETRY` columns go
    there as soon as each is made, the result keeping empty arrays of their types (the kept peaks'
    33 bytes are not held beside the prune, nor the ridges after it).
    ``node_z``, ``node_bmax``, ``node_nmin`` may be float32 (the tiled root's, when its values are raster
    values of a float32 raster: 12 bytes per node less): they are compared as they are and widened to
    float64 before any arithmetic or output, so the result is the float64 inputs' one.
    """
    n = node_key.size
    # canonical order: saddle from high to low, then the basin pair (monkey saddles list
    # several pairs at one cell; their order must not depend on how they were found)
    if not edges_sorted:  # the tiled engine's finalize sorts them itself, one array at a time
        order = saddle_order(ea, eb, ez, ekey, radix=True)
        if order.size > 1 and not (np.diff(order) == 1).all():
            ea, eb, ez, ekey = ea[order], eb[order], ez[order], ekey[order]
        del order
    bmax = np.full(n, -np.inf, node_bmax.dtype) if outside == "sea" else node_bmax
    in_tree, key_edge, parent, touched = _kernels.kruskal_sweep_like(node_z, node_key, ea, eb, ez, ekey, bmax,
                                                                     _kernels.index_like(n, ea.size))
    # the final prune reads no border or minimum values (empty arrays of their types: same compiled kernel)
    no_bmax, no_nmin = np.empty(0, bmax.dtype), np.empty(0, node_nmin.dtype)
    del bmax, node_bmax
    is_root = key_edge < 0
    # a domain whose cells all have the root's elevation is flat: no peak
    dom = _kernels.forest_components_like(n, ea, eb, in_tree, _kernels.index_like(n, ea.size))
    del in_tree  # the finalize of a 4 G-cell mosaic's root holds ~6.5 M nodes: free what is done
    flat_root = _kernels.flat_roots(dom, node_nmin, node_z, is_root)
    del node_nmin
    # kept: by blocks, each block's prominences made and let go (no whole prominence array: 8 bytes per
    # node; the kept peaks' own are made again below by the same expression)
    keep = np.empty(n, bool)
    step = 1 << 18
    for s0 in range(0, n, step):
        ke, root = key_edge[s0:s0 + step], is_root[s0:s0 + step]
        z = node_z[s0:s0 + step].astype(np.float64, copy=False)  # float32 nodes: compared, subtracted in float64
        below = ke >= 0
        prom = z.copy()
        prom[below] = z[below] - ez[ke[below]]
        k = np.where(root, (min_prominence_m <= 0) | (z >= min_prominence_m), prom >= min_prominence_m)
        k &= root | (prom > 0)
        k &= ~flat_root[s0:s0 + step] & node_ismax[s0:s0 + step]
        keep[s0:s0 + step] = k
        del prom, k
    del flat_root
    # a kept peak needs its parent: keep the root of every domain with a kept peak
    # (the root's prominence "= elevation" can be below the threshold when saddles
    # lie below zero)
    dom_has = np.zeros(n, bool)
    dom_has[dom[keep & ~is_root]] = True
    keep |= is_root & node_ismax & dom_has[dom]
    del dom, dom_has, node_ismax
    # the kept peaks' columns first (the prune does not change ``keep``), so the sweep's per-node
    # arrays are freed before the prune's own state exists (~26 bytes per node at a 6.5 M-node root);
    # each column is put in the store as soon as it is made
    index = _kernels.index_like(n, ea.size).dtype  # ids of nodes and of kept peaks: int32 while they fit
    kept = np.flatnonzero(keep).astype(index, copy=False)
    # kept peaks in raster order
    rank = np.argsort(node_key[kept], kind="stable")
    kept = kept[rank]
    del rank
    new_id = np.full(n, -1, index)
    new_id[kept] = np.arange(kept.size)
    nonroot = ~is_root[kept]
    del is_root
    kept_nonroot = kept[nonroot]
    edge_of = key_edge[kept_nonroot]
    del key_edge
    ks = np.full(kept.size, -1, np.int64)
    ks[nonroot] = ekey[edge_of]
    ks = _to_store(store, "key_saddle_cell", ks)
    ksz = np.full(kept.size, np.nan)
    ksz[nonroot] = ez[edge_of]
    ksz = _to_store(store, "key_saddle_z", ksz)
    kept_prom = node_z[kept].astype(np.float64, copy=False)  # the root's "prominence" is its elevation
    kept_prom[nonroot] = node_z[kept_nonroot].astype(np.float64, copy=False) - ez[edge_of]
    kept_prom = _to_store(store, "prominence", kept_prom)
    del edge_of
    par = np.full(kept.size, -1, np.int64)
    par[nonroot] = new_id[parent[kept_nonroot]]
    del parent, kept_nonroot
    par = _to_store(store, "parent", par)
    exact = ~touched[kept] & nonroot if outside == "unknown" else np.ones(kept.size, bool)
    del touched, nonroot
    exact = _to_store(store, "prominence_exact", exact)
    # every edge: of several edges at one saddle, the prune picks the same one in both engines
    oa, ob, oe, _, _, _ = _kernels.prune_edges(n, ea, eb, ez, ekey, keep, no_bmax, no_nmin, node_z, node_key, False,
                                               _kernels.index_like(n, ea.size))
    del ea, eb, keep
    # the output one array at a time, each source let go once taken (and put in the store)
    ridge_saddle_cell = _to_store(store, "ridge_saddle_cell", ekey[oe])
    del ekey
    ridge_saddle_z = _to_store(store, "ridge_saddle_z", ez[oe].astype(np.float64, copy=False))
    del ez, oe
    ridge_a = _to_store(store, "ridge_a", new_id[oa].astype(np.int64))
    del oa
    ridge_b = _to_store(store, "ridge_b", new_id[ob].astype(np.int64))
    del ob, new_id
    peak_cell = node_key[kept]
    del node_key
    peak_z = node_z[kept].astype(np.float64, copy=False)
    del node_z, kept
    return Orometry(
        shape=(int(shape[0]), int(shape[1])),
        n_maxima=int(n_maxima),
        peak_cell=peak_cell,
        peak_z=peak_z,
        prominence=kept_prom,
        key_saddle_cell=ks,
        key_saddle_z=ksz,
        parent=par,
        prominence_exact=exact,
        ridge_a=ridge_a,
        ridge_b=ridge_b,
        ridge_saddle_cell=ridge_saddle_cell,
        ridge_saddle_z=ridge_saddle_z,
    )


def _to_store(store: Any, name: str, values: np.ndarray) -> np.ndarray:
    """``values`` put in the column ``store`` as column ``name``, then an empty array of their type
    (without a store, ``values``)."""
    if store is None:
        return values
    store.put(name, values)
    return np.empty(0, values.dtype)


def saddle_order(ea: np.ndarray, eb: np.ndarray, ez: np.ndarray, ekey: np.ndarray, *,
                 radix: bool = False) -> np.ndarray:
    """The edges' order by saddle from high to low, then basin pair: ``np.lexsort((eb, ea, ekey, -ez))``.

    When every elevation is a float32 and every cell fits in 32 bits (the in-memory engine, and the
    tiled engine's root, whose edges above every saddle carry keys ``-1 - cell``:
    :func:`~orokit.topology._kernels.saddle_key`), one argsort of a 64-bit key (elevation bits,
    descending, then cell) and a sort of the edges sharing a cell (monkey saddles) only: ~16 bytes per
    edge beside the order instead of the lexsort's ~28, and a fraction of its time; otherwise the
    4-key lexsort. ``radix``: that argsort by :func:`~orokit.topology._kernels.radix_argsort` (a third
    of numpy's time on 1 M edges; 16 bytes per edge more meanwhile: the in-memory finalize's, serial).
    """
    z32 = ez.astype(np.float32) + np.float32(0.0)  # + 0: -0.0 and 0.0 are one elevation
    if ekey.size == 0 or not np.array_equal(z32, ez):
        return np.lexsort((eb, ea, ekey, -ez))
    bits = z32.view(np.uint32)
    up = np.where(bits >> np.uint32(31) == 1, ~bits, bits | np.uint32(0x80000000))  # ascending with z
    del z32, bits
    key = _kernels.saddle_key(up, ekey, ez)
    del up
    if key.size != ekey.size or (ea.size and max(int(ea.max()), int(eb.max())) >= 2**31):
        return np.lexsort((eb, ea, ekey, -ez))
    if radix:
        order = _radix_argsort(key)  # key sorted in place
    else:
        order = np.argsort(key)
    _kernels.sort_saddle_ties(order, key, ea, eb, radix)
    return order


#: keys from which :func:`saddle_order`'s radix argsort sorts two halves on two threads and merges them (numba
#: has two threads or more): the in-memory finalize's sort (serial) in about half its time on two cores
PARALLEL_SORT_KEYS = 1 << 16


def _radix_argsort(key: np.ndarray) -> np.ndarray:
    """:func:`~orokit.topology._kernels.radix_argsort` of ``key`` (sorted in place); from
    :data:`PARALLEL_SORT_KEYS` keys on two numba threads or more, its halves on two threads, then merged
    (:func:`~orokit.topology._kernels.merge_sorted_halves`): the same order (both are stable), no more memory
    (28 bytes per key at most against the whole sort's 32)."""
    n = key.size
    if n < PARALLEL_SORT_KEYS or _threads() < 2:
        return _kernels.radix_argsort(key)
    from concurrent.futures import ThreadPoolExecutor

    h = n // 2
    with ThreadPoolExecutor(1) as pool:
        second = pool.submit(_kernels.radix_argsort, key[h:])
        first = _kernels.radix_argsort(key[:h])
        rest = second.result()
    return _kernels.merge_sorted_halves(key, first, rest, h)


#: the isolation table's columns as the peak rows read them (name, dtype)
ISOLATION_ARRAYS = (("isolation", np.float64), ("isolation_row", np.int64), ("isolation_col", np.int64),
                    ("isolation_exact", np.bool_))

#: the engine output's columns that the isolation search does not read: they can wait in a column store
#: (:func:`spill_orometry`) from the end of the chunk pass until the tables read them back
SPILLED_OROMETRY = ("prominence", "key_saddle_cell", "key_saddle_z", "parent", "prominence_exact",
                    "ridge_a", "ridge_b", "ridge_saddle_cell", "ridge_saddle_z")


def spill_orometry(core: Orometry, store: Any) -> None:
    """Move ``core``'s :data:`SPILLED_OROMETRY` columns to the column ``store`` (``core`` keeps empty
    arrays of their types; a column already in the store is not written again).

    What the chunked ``orokit analyze`` holds of the engine output during the isolation search is then
    the peaks' cells and elevations (16 bytes per peak instead of ~81); :func:`build_result` reads the
    rest back when it makes the tables.
    """
    for f in SPILLED_OROMETRY:
        values = getattr(core, f)
        if f not in store:
            store.put(f, values)
        # a new empty array, not ``values[:0]``: a view would keep the whole column alive
        setattr(core, f, np.empty(0, values.dtype))


def build_result(core: Orometry, *, transform, crs, isolation: pd.DataFrame | None,
                 geometry: bool = True, blocks: bool = False, store: Any = None) -> AnalysisResult:
    """Peaks/saddles tables and the DivideTree from the raw engine output.

    ``geometry=False``: plain DataFrames without point geometries (``x``/``y`` hold the
    places; the files written are the same), ~45 % less memory per peak.
    ``blocks=True``: the peaks table is a :class:`~orokit.topology.tables.TableBlocks`
    whose rows are made from the engine's arrays by blocks when written (no geometry;
    the same rows and files; ~130 bytes per peak less held at once); the saddles table and
    the tree's frames are TableBlocks whose places are made from the cells
    (:class:`~orokit.topology.tables.CellPlaces`: 16 bytes per peak and per saddle held).
    ``store`` (with ``blocks``): a column store (``put(name, values)``, ``rows(name, start, stop)``,
    ``column(name)``, ``name in store``; :class:`orokit.io.spill_io.SpilledColumns`) where the peak
    table's own columns wait while the files are written, each block reading its rows back: ``core``'s
    :data:`SPILLED_OROMETRY` columns are moved there first (:func:`spill_orometry`; ``core`` is consumed,
    a caller may have moved them before), read back one at a time when the saddles, ridges and parents
    are made and let go once used; the line and prominence parents go there too. The isolation's columns
    (:data:`ISOLATION_ARRAYS`) are read from the store when it holds them (the caller moved them;
    ``isolation`` is then None).
    """
    import pandas as pd  # here, not at import: the engine's peak memory is reached without it

    H, W = core.shape

    n = core.n_kept
    elev = core.peak_z.astype(np.float64, copy=False)
    moved = store is not None and blocks and n > 0
    if moved:  # the columns only the rows read wait in the store; the others come back one at a time
        spill_orometry(core, store)

    def take(name: str) -> np.ndarray:
        return store.column(name) if moved else getattr(core, name)

    # saddles of the pruned tree, in raster order (a monkey saddle serves several ridges)
    ridge_cell = take("ridge_saddle_cell")
    sc_sorted, first = np.unique(ridge_cell, return_index=True)
    ridge_sid = np.searchsorted(sc_sorted, ridge_cell)
    del ridge_cell
    sad_z = take("ridge_saddle_z")[first].astype(np.float64)
    del first
    key_saddle = take("key_saddle_cell")
    edges = pd.DataFrame({"peak_a": take("ridge_a"), "peak_b": take("ridge_b"), "saddle": ridge_sid}, copy=False)
    del ridge_sid
    line = prom_parent = None
    if moved:  # the saddles' cells wait in the store while the parents are found (8 bytes per saddle)
        store.put("saddle_cell", sc_sorted)
        del sc_sorted
    if n:
        # the parents read only the elevations and the ridges: found on a tree of those alone, before
        # the places of peaks and saddles exist (~64 bytes per peak less under the sweeps' transient)
        bare = DivideTree(pd.DataFrame({"x": elev, "y": elev, "elevation": elev}, copy=False),
                          pd.DataFrame({"x": sad_z, "y": sad_z, "elevation": sad_z}, copy=False), edges)
        # the engine's prominences and roots are the pruned tree's (pruning keeps every kept peak's
        # prominence; a root is the highest peak of its domain): no second Kruskal sweep over the tree
        # for them (~100 bytes per peak of sorted edge copies and sweep state at the tables' peak)
        known = pd.DataFrame({"prominence": take("prominence"), "key_saddle": key_saddle}, copy=False)
        parents = bare.parents(known)
        del known
        del bare
        line = parents["line_parent"].to_numpy(np.int64)
        prom_parent = parents["prominence_parent"].to_numpy(np.int64)
        del parents
        if moved:  # the parents wait with the rest of the rows' own columns
            store.put("line_parent", line)
            store.put("prominence_parent", prom_parent)
            line = prom_parent = None
    if moved:
        sc_sorted = store.column("saddle_cell")
    key_of = np.full(sc_sorted.size, -1, np.int64)  # the peak whose key saddle each saddle is (-1 for none)
    for s0 in range(0, key_saddle.size, 1 << 18):  # by blocks of peaks, in order: no whole gathers beside key_of
        ks = key_saddle[s0:s0 + (1 << 18)]
        kp = np.flatnonzero(ks >= 0)
        key_of[np.searchsorted(sc_sorted, ks[kp])] = kp + s0
        del ks, kp
    del key_saddle
    # the places (row, col, x, y, elevation) of peaks and saddles from their cells and elevations: with
    # ``blocks`` made when read (the tree's frames and both tables are TableBlocks: 16 bytes per peak and
    # per saddle held instead of 40; the files are written by blocks), otherwise made whole once
    places = CellPlaces(core.peak_cell, core.peak_z, W, transform)
    s_places = CellPlaces(sc_sorted, sad_z, W, transform)
    del sc_sorted, sad_z, elev
    if blocks:
        make = _peak_rows(core, places, line, prom_parent, isolation, transform, crs, store if moved else None)
        tree = DivideTree(
            TableBlocks(n, places.frame, index_name="peak_id", places=places),
            TableBlocks(len(s_places), s_places.frame, index_name="saddle_id", places=s_places),
            edges, crs, {"units": "m"},
        )
        peaks: Any = TableBlocks(n, make, index_name="peak_id", places=places)
        saddles: Any = TableBlocks(len(s_places), lambda i, j: s_places.frame(i, j, "saddle_id", {"key_of": key_of}),
                                   index_name="saddle_id", places=s_places)
    else:
        pf, sf = places.frame(0, n), s_places.frame(0, len(s_places))
        # copy=False: the tree's frames and the tables share these columns (pandas copies on write)
        tree = DivideTree(pf, sf, edges, crs, {"units": "m"})
        make = _peak_rows(core, places, line, prom_parent, isolation, transform, crs, store if moved else None,
                          whole=pf)
        peaks = make(0, n)
        saddles = pd.DataFrame({**{c: sf[c].to_numpy() for c in sf.columns}, "key_of": key_of}, copy=False)
        saddles.index.name = "saddle_id"
    assert list(saddles.columns) == SADDLE_COLUMNS
    if geometry and not blocks:
        import geopandas as gpd

        peaks = gpd.GeoDataFrame(peaks, geometry=gpd.points_from_xy(pf["x"], pf["y"]), crs=crs)
        saddles = gpd.GeoDataFrame(saddles, geometry=gpd.points_from_xy(sf["x"], sf["y"]), crs=crs)
    validate_peak_table(peaks)
    validate_saddle_table(saddles)
    return AnalysisResult(peaks, saddles, tree, crs, {})


def _peak_rows(core: Orometry, places: CellPlaces, line: np.ndarray | None, prom_parent: np.ndarray | None,
               isolation: pd.DataFrame | None, transform, crs, store: Any = None, whole: Any = None):
    """``make(start, stop)``: rows ``start:stop`` of the peaks table (:data:`PEAK_COLUMNS`, index
    ``peak_id``) from whole arrays held once (the engine's, the isolation's, the places' cells and
    elevations and the parents); every other column is made for the rows asked. Thread-safe (writers
    run in two threads). ``whole``: a frame of the places' columns already made (shared, not made again).
    ``store``: the engine's row-only columns, the parents and the isolation (when there) are read
    from it by rows (see :func:`build_result`).
    """
    import threading

    import pandas as pd

    W = core.shape[1]
    n = core.n_kept
    # the engine's columns the rows need, not ``core``: its ridge arrays and cells (24 bytes per peak)
    # are free once the tables exist, while the blocks live until the files are written
    held: dict[str, Any] = {}
    if store is None:
        held = {"prominence": core.prominence, "key_saddle_cell": core.key_saddle_cell,
                "key_saddle_z": core.key_saddle_z, "parent": core.parent,
                "prominence_exact": core.prominence_exact, "line_parent": line, "prominence_parent": prom_parent}
    has_parents = line is not None or store is not None

    def col(name: str, sl: slice) -> np.ndarray:
        return held[name][sl] if store is None else store.rows(name, sl.start, sl.stop)

    iso: Any = None
    if isolation is not None and n:
        # the isolation table's own columns, no copies (the caller drops it)
        iso = tuple(isolation[c].to_numpy(t) for c, t in ISOLATION_ARRAYS)
    elif store is not None and n and ISOLATION_ARRAYS[0][0] in store:
        iso = store
    local = threading.local()  # one pyproj Transformer per thread (they are not shared between threads)

    def place(name: str, at: Any) -> np.ndarray:
        return places.values(name, at) if whole is None else whole[name].to_numpy()[at]

    def xy(r, c):
        return (transform.c + (c + 0.5) * transform.a + (r + 0.5) * transform.b,
                transform.f + (c + 0.5) * transform.d + (r + 0.5) * transform.e)

    def make(start: int, stop: int) -> pd.DataFrame:
        m = stop - start
        sl = slice(start, stop)

        def none_id():  # a fresh array per column: with copy=False below, columns must not share memory
            return np.full(m, -1, np.int64)

        def nan():
            return np.full(m, np.nan)

        def cell_of(ids):
            """row and col of peak ids (-1 for none)."""
            has = ids >= 0
            idx = np.maximum(ids, 0)
            return np.where(has, place("row", idx) if n else 0, -1), np.where(has, place("col", idx) if n else 0, -1)

        e = place("elevation", sl)
        prom = col("prominence", sl)
        ksc = col("key_saddle_cell", sl)
        has_saddle = ksc >= 0
        ks = np.where(has_saddle, ksc, 0)
        k_rows = np.where(has_saddle, ks // W, -1)
        k_cols = np.where(has_saddle, ks % W, -1)
        kx, ky = xy(k_rows, k_cols)
        del ks
        ln = col("line_parent", sl) if has_parents else none_id()
        pp = col("prominence_parent", sl) if has_parents else none_id()
        iso_d, iso_r, iso_c, iso_x, iso_y = nan(), none_id(), none_id(), nan(), nan()
        iso_exact = np.zeros(m, bool)
        if iso is not None:
            if iso is store:
                iso_d, iso_r, iso_c, iso_exact = (store.rows(c, start, stop) for c, _ in ISOLATION_ARRAYS)
            else:
                iso_d, iso_r, iso_c, iso_exact = (a[sl] for a in iso)
            ix, iy = xy(iso_r, iso_c)
            found = iso_r >= 0
            iso_x, iso_y = np.where(found, ix, np.nan), np.where(found, iy, np.nan)
            del ix, iy, found
        parent = col("parent", sl).astype(np.int64, copy=False)
        island_rc, line_rc, prom_rc = cell_of(parent), cell_of(ln), cell_of(pp)
        px, py = place("x", sl), place("y", sl)
        lon, lat = nan(), nan()
        if crs is not None and m:
            if getattr(local, "transformer", None) is None:
                from pyproj import Transformer

                local.transformer = Transformer.from_crs(crs, "EPSG:4326", always_xy=True)
            lon, lat = local.transformer.transform(px, py)
        columns = {
            "row": place("row", sl),
            "col": place("col", sl),
            "x": px,
            "y": py,
            "lon": lon,
            "lat": lat,
            "elevation": e,
            "prominence": prom.astype(np.float64, copy=False),
            "saddle_row": k_rows,
            "saddle_col": k_cols,
            "saddle_x": np.where(has_saddle, kx, np.nan),
            "saddle_y": np.where(has_saddle, ky, np.nan),
            "saddle_elevation": col("key_saddle_z", sl).astype(np.float64, copy=False),
            "island_parent": parent,
            "island_parent_row": island_rc[0],
            "island_parent_col": island_rc[1],
            "line_parent": ln,
            "line_parent_row": line_rc[0],
            "line_parent_col": line_rc[1],
            "prominence_parent": pp,
            "prominence_parent_row": prom_rc[0],
            "prominence_parent_col": prom_rc[1],
            "dominance": np.where(e > 0, prom / np.where(e > 0, e, 1.0), np.nan),
            "isolation": iso_d,
            "isolation_row": iso_r,
            "isolation_col": iso_c,
            "isolation_x": iso_x,
            "isolation_y": iso_y,
            "prominence_exact": col("prominence_exact", sl).astype(bool, copy=False),
            "isolation_exact": iso_exact,
        }
        assert list(columns) == PEAK_COLUMNS
        # copy=False: one block per column, no consolidated copy of the whole table
        frame = pd.DataFrame(columns, index=pd.RangeIndex(start, stop, name="peak_id"), copy=False)
        return frame

    return make
