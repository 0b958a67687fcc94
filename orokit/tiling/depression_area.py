"""Out-of-core area below the spill level of every depression (``area_m2``).

The area of a pit ``p`` (a peak of the engine grid ``g = -h``) is the area of its
*lake*: the component of ``{g > s_p}`` that holds ``p``, with ``s_p`` its key saddle
value in ``g`` (the in-memory :func:`orokit.topology.depressions.spill_areas`). Lakes
of the kept pits are nested, so a cell lies in a chain of lakes; its area goes to the
smallest one and each lake's area is the sum over its sub-lakes.

Chunk by chunk, in one pass over the raster, with memory of one chunk plus the chunk
borders:

1. Every chunk sweeps its cells from high to low (union-find) and keeps a
   bottleneck tree over its *nodes*: the kept pits in it and its cells on sides
   facing other chunks (edge weight = the lowest value on the best path). The same
   sweep charges every cell's area to a node: a cell of value ``v`` connected
   (through cells >= v) to node ``y`` is charged to ``(y, v)``; a chunk component
   without a node holds no kept pit, so its cells wait until it meets a node at value
   ``u`` and are charged to ``(y, u)``. The lakes close at the spill values of the
   kept pits, which are known before the pass, so a charge only needs the *bucket*
   of its value among those levels: the chunk returns the sums per (node, bucket).
2. The chunk trees and the seam edges between facing border cells (weight = the
   lower cell) form a graph whose Kruskal sweep from high to low gives the exact
   bottleneck between any two nodes of the raster. Closing each lake at ``s_p``
   (after the edges above ``s_p``, before the ones at ``s_p``) tells, for every
   node, the smallest lake holding it, and every lake's parent lake.
3. A charge ``(y, bucket of v)`` belongs to the first lake on ``y``'s chain whose
   level is below ``v`` (the bucket decides that comparison for every level); each
   lake's area is then the sum over its sub-lakes.

Sums run in another order than the in-memory flooding, so areas agree with it up to
floating-point rounding of the sum.
"""
from __future__ import annotations

import logging
from typing import Any

import numpy as np
from numba import njit

from orokit.topology._kernels import _NEIGHBOURS_8, _find  # the in-memory kernels' union-find and neighbours

logger = logging.getLogger(__name__)

__all__ = ["tiled_spill_areas"]


@njit(cache=True, nogil=True)
def _advance(q, b, lake_par, lake_b):
    """First lake on the chain from ``q`` (itself, then parents) whose level is below the
    values of bucket ``b`` (``lake_b``: the bucket index of each lake's level)."""
    while q >= 0 and lake_b[q] >= b:
        q = lake_par[q]
    return q


@njit(cache=True, nogil=True)
def _push(rn, rb, ra, nrec, y, b, a):
    """Append the charge (node y, bucket b, area a), growing the arrays when full."""
    if nrec == rn.size:
        cap = 2 * rn.size
        rn2 = np.empty(cap, np.int64)
        rb2 = np.empty(cap, np.int64)
        ra2 = np.empty(cap)
        rn2[:nrec] = rn[:nrec]
        rb2[:nrec] = rb[:nrec]
        ra2[:nrec] = ra[:nrec]
        rn, rb, ra = rn2, rb2, ra2
    rn[nrec] = y
    rb[nrec] = b
    ra[nrec] = a
    return rn, rb, ra, nrec + 1


@njit(cache=True, nogil=True)
def _chunk_sweep(g, order, nvalid, node, row_area, levels):
    """One high-to-low sweep of a chunk (``g``: its cells, NaN = nodata).

    ``node``: local node index of each cell (-1 if none); ``levels``: the lakes' closing
    values, sorted. Returns the bottleneck tree over the nodes as (a, b, w) arrays and
    the area charges as (node, bucket, area) arrays: the bucket of a value ``v`` is the
    number of levels below ``v``; the charges of one node and bucket are summed while
    they come in a row.
    """
    h, w = g.shape
    n = h * w
    uf = np.full(n, -1, np.int32)  # int32: a chunk has < 2**31 cells (and 4 bytes less per cell each)
    size = np.zeros(n, np.int32)
    anchor = np.full(n, -1, np.int32)
    bucket = np.full(n, -1, np.int32)  # open bucket of an anchored root
    pend = np.zeros(n)  # area waiting for a node (root without anchor) or open sum (anchored root)
    nn = 0
    for k in range(n):
        if node.ravel()[k] >= 0:
            nn += 1
    ea = np.empty(max(nn - 1, 0), np.int64)
    eb = np.empty(max(nn - 1, 0), np.int64)
    ew = np.empty(max(nn - 1, 0))
    ne = 0
    rn = np.empty(max(2 * nn, 16), np.int64)
    rb = np.empty(rn.size, np.int64)
    ra = np.empty(rn.size)
    nrec = 0
    gf = g.ravel()
    nf = node.ravel()
    roots = np.empty(8, np.int64)
    p = levels.size  # bucket of the current value: levels[p - 1] < v <= levels[p]
    for k in range(nvalid):
        c = order[k]
        v = gf[c]
        while p > 0 and levels[p - 1] >= v:
            p -= 1
        r = c // w
        q = c % w
        uf[c] = c
        size[c] = 1
        nd = nf[c]
        pend[c] = row_area[r]
        if nd >= 0:
            anchor[c] = nd
            bucket[c] = p
        nr = 0
        for dr, dc in _NEIGHBOURS_8:
            rr = r + dr
            cc = q + dc
            if rr < 0 or rr >= h or cc < 0 or cc >= w:
                continue
            nb = rr * w + cc
            if uf[nb] < 0:
                continue
            rt = _find(uf, nb)
            seen = False
            for t in range(nr):
                if roots[t] == rt:
                    seen = True
            if not seen:
                roots[nr] = rt
                nr += 1
        for t in range(nr):
            x = _find(uf, c)
            y = roots[t]
            if x == y:
                continue
            if size[x] < size[y]:
                x, y = y, x
            # merge y into x at level v
            if anchor[x] >= 0 and anchor[y] >= 0:
                ea[ne] = anchor[x]
                eb[ne] = anchor[y]
                ew[ne] = v
                ne += 1
                if pend[y] != 0.0:  # y's open sum is complete
                    rn, rb, ra, nrec = _push(rn, rb, ra, nrec, anchor[y], bucket[y], pend[y])
                pend[y] = 0.0
            elif anchor[x] >= 0 or anchor[y] >= 0:
                if anchor[x] < 0:
                    anchor[x] = anchor[y]
                    bucket[x] = bucket[y]
                    pend[x], pend[y] = pend[y], pend[x]
                # the waiting area of y meets node anchor[x] at level v (bucket p)
                if bucket[x] != p:
                    if pend[x] != 0.0:
                        rn, rb, ra, nrec = _push(rn, rb, ra, nrec, anchor[x], bucket[x], pend[x])
                    bucket[x] = p
                    pend[x] = pend[y]
                else:
                    pend[x] += pend[y]
                pend[y] = 0.0
            else:
                pend[x] += pend[y]
                pend[y] = 0.0
            uf[y] = x
            size[x] += size[y]
    for k in range(nvalid):
        c = order[k]
        if uf[c] == c and anchor[c] >= 0 and pend[c] != 0.0:
            rn, rb, ra, nrec = _push(rn, rb, ra, nrec, anchor[c], bucket[c], pend[c])
    return ea[:ne], eb[:ne], ew[:ne], rn[:nrec].copy(), rb[:nrec].copy(), ra[:nrec].copy()


@njit(cache=True, nogil=True)
def _assign(rec_node, rec_bucket, rec_area, lake_of_node, lake_par, lake_b, acc):
    """Add every charge to the smallest lake of its node whose level is below its value."""
    for i in range(rec_node.size):
        q = _advance(lake_of_node[rec_node[i]], rec_bucket[i], lake_par, lake_b)
        if q >= 0:
            acc[q] += rec_area[i]


@njit(cache=True, nogil=True)
def _lake_forest(n_nodes, ea, eb, ew, close_node, close_s):
    """Kruskal sweep (high to low) of the node graph, closing lake ``k`` at ``close_s[k]``.

    Edges above a lake's level join before it closes, edges at its level after.
    Returns (smallest lake of each node or -1, parent lake of each lake or -1, lakes
    in closing order). ``close_node[k] < 0`` marks a lake that never closes.
    """
    ne = ea.size
    nl = close_node.size
    eo = np.argsort(-ew, kind="mergesort")
    lo = np.argsort(-close_s, kind="mergesort")
    total = n_nodes + ne + nl
    uf = np.arange(n_nodes)
    krt = np.arange(n_nodes)  # current tree node of each union-find root
    parent = np.full(total, -1, np.int64)
    label = np.full(total, -1, np.int64)
    lake_node = np.full(nl, -1, np.int64)
    closed = np.empty(nl, np.int64)
    nc = 0
    m = n_nodes
    i = 0
    j = 0
    while j < nl and close_node[lo[j]] < 0:
        j += 1
    while i < ne or j < nl:
        if j < nl and (i >= ne or ew[eo[i]] <= close_s[lo[j]]):
            k = lo[j]
            j += 1
            while j < nl and close_node[lo[j]] < 0:
                j += 1
            r = _find(uf, close_node[k])
            t = krt[r]
            if label[t] >= 0:
                parent[t] = m
                krt[r] = m
                t = m
                m += 1
            label[t] = k
            lake_node[k] = t
            closed[nc] = k
            nc += 1
        else:
            e = eo[i]
            i += 1
            ra = _find(uf, ea[e])
            rb = _find(uf, eb[e])
            if ra == rb:
                continue
            parent[krt[ra]] = m
            parent[krt[rb]] = m
            uf[rb] = ra
            krt[ra] = m
            m += 1
    nearest = np.full(m, -1, np.int64)
    for t in range(m - 1, -1, -1):
        if label[t] >= 0:
            nearest[t] = label[t]
        elif parent[t] >= 0:
            nearest[t] = nearest[parent[t]]
    lake_par = np.full(nl, -1, np.int64)
    for k in range(nl):
        t = lake_node[k]
        if t >= 0 and parent[t] >= 0:
            lake_par[k] = nearest[parent[t]]
    return nearest[:n_nodes].copy(), lake_par, closed[:nc].copy()


def _side_cells(region: tuple[int, int, int, int], shape: tuple[int, int]) -> np.ndarray:
    """Global flat index of the cells of ``region`` on sides that face other chunks (sorted)."""
    r0, r1, c0, c1 = region
    H, W = shape
    rows, cols = np.arange(r0, r1), np.arange(c0, c1)
    mask = np.zeros((r1 - r0, c1 - c0), bool)
    if r0 > 0:
        mask[0] = True
    if r1 < H:
        mask[-1] = True
    if c0 > 0:
        mask[:, 0] = True
    if c1 < W:
        mask[:, -1] = True
    rr, cc = np.nonzero(mask)
    return np.sort(rows[rr] * W + cols[cc])


def _chunk_nodes(block: np.ndarray, region, shape, pit_keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Node keys of a chunk (valid side cells and kept pits, sorted) and the local node grid."""
    r0, r1, c0, c1 = region
    W = shape[1]
    keys = np.union1d(_side_cells(region, shape), pit_keys)
    lr, lc = keys // W - r0, keys % W - c0
    keep = ~np.isnan(block[lr, lc])
    keys, lr, lc = keys[keep], lr[keep], lc[keep]
    node = np.full(block.shape, -1, np.int32)
    node[lr, lc] = np.arange(keys.size)
    return keys, node


def _sorted_cells(block: np.ndarray) -> tuple[np.ndarray, int]:
    """Cells from high to low, NaN last. The order among equal values does not matter: the
    sweep works by value (every cell above ``v`` is joined before any cell at ``v``)."""
    flat = block.ravel()
    valid = ~np.isnan(flat)
    return np.argsort(np.where(valid, -flat, np.inf)), int(valid.sum())


class _Block:
    """One chunk as a small dask array read inside its own task (opaque to the outer graph)."""

    def __init__(self, data, region):
        r0, r1, c0, c1 = region
        self.array = data[r0:r1, c0:c1]

    def read(self) -> np.ndarray:
        """The chunk's values as float32 when stored so (exact, and a faster sort), else float64."""
        a = np.asarray(self.array.compute(scheduler="sync"))
        return np.ascontiguousarray(a if a.dtype == np.float32 else a.astype(np.float64))


def _chunk_task(data, region, shape, pit_keys, row_area, levels) -> tuple:
    """The pass over one chunk: node keys, bottleneck tree (global keys), the nodes' values
    and the area charges (global node keys, buckets, areas)."""
    r0, r1, c0, c1 = region
    block = data.read()
    keys, node = _chunk_nodes(block, region, shape, pit_keys)
    order, nvalid = _sorted_cells(block)
    a, b, w, rn, rb, ra = _chunk_sweep(block, order, nvalid, node, row_area[r0:r1], levels)
    vals = block.ravel()[(keys // shape[1] - r0) * (c1 - c0) + keys % shape[1] - c0].astype(np.float64)
    return keys, keys[a], keys[b], w, vals, keys[rn], rb, ra


def _seam_edges(keys: np.ndarray, vals: np.ndarray, W: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Edges between 8-neighbouring node cells (weight = the lower value), each pair once.

    Neighbours inside one chunk are joined too; that is harmless (the chunk tree
    already holds a path at least as high).
    """
    pos = np.arange(keys.size)
    ea, eb, ew = [], [], []
    r, c = keys // W, keys % W
    for dr, dc in ((0, 1), (1, -1), (1, 0), (1, 1)):
        rr, cc = r + dr, c + dc
        ok = (cc >= 0) & (cc < W)
        nk = rr * W + cc
        j = np.searchsorted(keys, nk)
        j = np.minimum(j, keys.size - 1)
        hit = ok & (keys[j] == nk)
        ea.append(pos[hit])
        eb.append(j[hit])
        ew.append(np.minimum(vals[hit], vals[j[hit]]))
    return np.concatenate(ea), np.concatenate(eb), np.concatenate(ew)


def tiled_spill_areas(g, pit_row: np.ndarray, pit_col: np.ndarray, pit_value: np.ndarray, spill_value: np.ndarray,
                      row_area_m2: np.ndarray, *, compute: Any = None) -> np.ndarray:
    """Area (m²) of each pit's lake, computed chunk by chunk on the dask array ``g``.

    ``g`` is the engine grid (the peaks of ``g`` are the pits, NaN = nodata), the pits
    are kept peaks of ``g`` at ``pit_row/col`` with value ``pit_value`` and key saddle
    value ``spill_value`` (NaN for a pit that never spills: its area is NaN).
    ``row_area_m2`` is the cell area of every row; ``compute`` a function computing a
    list of dask objects (:func:`orokit.tiling.engine.get_compute`). Equal to
    :func:`orokit.topology.depressions.spill_areas` up to the rounding of the sums.
    """
    import dask

    if compute is None:
        from orokit.tiling.engine import get_compute

        compute = get_compute(None)
    H, W = g.shape
    pit_row, pit_col = np.asarray(pit_row, np.int64), np.asarray(pit_col, np.int64)
    pit_value, spill_value = np.asarray(pit_value, np.float64), np.asarray(spill_value, np.float64)
    row_area = np.asarray(row_area_m2, np.float64)
    rb = np.concatenate([[0], np.cumsum(g.chunks[0])]).astype(int)
    cb = np.concatenate([[0], np.cumsum(g.chunks[1])]).astype(int)
    pit_keys = pit_row * W + pit_col
    cbi = np.searchsorted(rb, pit_row, side="right") - 1
    cbj = np.searchsorted(cb, pit_col, side="right") - 1
    regions, pits = [], []
    for i in range(len(rb) - 1):
        for j in range(len(cb) - 1):
            regions.append((int(rb[i]), int(rb[i + 1]), int(cb[j]), int(cb[j + 1])))
            pits.append(np.sort(pit_keys[(cbi == i) & (cbj == j)]))
    # a lake closes at its spill value; a pit at its spill value has an empty lake
    closes = np.isfinite(spill_value) & (pit_value > spill_value)
    levels = np.unique(spill_value[closes])
    ra, lv = dask.delayed(row_area), dask.delayed(levels)
    chunks = compute([dask.delayed(_chunk_task)(_Block(g, reg), reg, (H, W), pk, ra, lv)
                      for reg, pk in zip(regions, pits)])
    keys = np.concatenate([t[0] for t in chunks])
    vals = np.concatenate([t[4] for t in chunks])
    keys, first = np.unique(keys, return_index=True)
    vals = vals[first]
    ea = np.searchsorted(keys, np.concatenate([t[1] for t in chunks]))
    eb = np.searchsorted(keys, np.concatenate([t[2] for t in chunks]))
    ew = np.concatenate([t[3] for t in chunks])
    rec_node = np.searchsorted(keys, np.concatenate([t[5] for t in chunks]))
    rec_bucket = np.concatenate([t[6] for t in chunks])
    rec_area = np.concatenate([t[7] for t in chunks])
    del chunks
    sa, sb, sw = _seam_edges(keys, vals, W)
    ea, eb, ew = np.concatenate([ea, sa]), np.concatenate([eb, sb]), np.concatenate([ew, sw])
    close_node = np.where(closes, np.searchsorted(keys, pit_keys), -1).astype(np.int64)
    close_s = np.where(closes, spill_value, -np.inf)
    lake_of_node, lake_par, closed = _lake_forest(keys.size, ea, eb, ew, close_node, close_s)
    del ea, eb, ew, sa, sb, sw
    logger.info("depression areas: %d chunk-border nodes, %d lakes, %d area charges", keys.size,
                int(closes.sum()), rec_node.size)
    lake_b = np.where(closes, np.searchsorted(levels, np.where(closes, spill_value, 0.0)), -1).astype(np.int64)
    acc = np.zeros(pit_keys.size)
    _assign(rec_node, rec_bucket, rec_area, lake_of_node, lake_par, lake_b, acc)
    for k in closed:  # children close before their parents
        if lake_par[k] >= 0:
            acc[lake_par[k]] += acc[k]
    out = np.where(closes, acc, np.nan)
    out[np.isfinite(spill_value) & ~closes] = 0.0
    return out
