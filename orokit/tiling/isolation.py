"""Isolation over a chunked raster: the search for higher ground crosses chunk borders.

Each chunk's maximum (and whether it holds NaN) is computed once. For every peak the
chunks are visited by increasing lower bound of their distance, skipping chunks
whose maximum is not strictly higher; inside a chunk the block-maximum pyramid search
of :mod:`orokit.metrics._kernels` runs with the peak given relative to the chunk.
Peaks are handled in spatially sorted batches so a chunk is loaded a few times at
most; memory stays at one chunk plus the batch.
"""
from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np
import pandas as pd

from orokit.metrics import _kernels as _mk
from orokit.metrics._kernels import EARTH_RADIUS_M
from orokit.metrics.isolation import KernelMetric, finish_isolation
from orokit.tiling.memory import release_free_heap

logger = logging.getLogger(__name__)

__all__ = ["tiled_isolation", "chunk_isolation", "block_stats", "cell_places", "SettledIsolation"]

_BATCH = 4096
_BOUNDS_CELLS = 2**20  # peaks x chunks of one batch's distance bounds (8 MB each array): flat in the chunk count
_CACHE_BYTES = 256 * 2**20  # chunks and pyramids kept by the cross-chunk search
_FINISH_ROWS = 2**18  # peaks per block of the final choice among candidates (its arrays: ~100 bytes per peak)


def _chunk_bounds(rows, cols, rb, cb, metric: KernelMetric) -> np.ndarray:
    """Lower bound of the distance from each cell to each chunk (n x nchunks)."""
    r0, r1 = rb[:-1], rb[1:] - 1
    c0, c1 = cb[:-1], cb[1:] - 1
    R0, C0 = np.meshgrid(r0, c0, indexing="ij")
    R1, C1 = np.meshgrid(r1, c1, indexing="ij")
    R0, R1, C0, C1 = (a.ravel()[None, :] for a in (R0, R1, C0, C1))
    pr, pc = rows[:, None], cols[:, None]
    gr = np.maximum(0, np.maximum(R0 - pr, pr - R1))
    gc = np.maximum(0, np.maximum(C0 - pc, pc - C1))
    if not metric.geo:
        return np.hypot(gr * metric.dy, gc * metric.dx)
    lat = lambda r: np.abs(metric.lat0 + (r + 0.5) * metric.dlat)  # noqa: E731
    phimax = np.minimum(np.maximum(lat(pr), np.maximum(lat(R0), lat(R1))), np.pi / 2)
    s = np.sin(gr * abs(metric.dlat) / 2) ** 2 + np.cos(phimax) ** 2 * np.sin(gc * abs(metric.dlon) / 2) ** 2
    return 2 * EARTH_RADIUS_M * np.arcsin(np.minimum(1.0, np.sqrt(s)))


class _BlockCache:
    """Loaded chunks and their search pyramids, kept within a memory budget (peaks are
    processed chunk by chunk in raster order, so neighbouring chunks are usually still
    here). The NaN pyramid of a chunk is built only when a search asks for it."""

    def __init__(self, blocks, nbx: int, compute, has_nan: np.ndarray, budget_bytes: int | None = None):
        self.blocks, self.nbx, self.compute = blocks, nbx, compute
        self.budget = _CACHE_BYTES if budget_bytes is None else budget_bytes
        self.has_nan = has_nan
        self.entries: dict[int, dict] = {}
        self.loads = 0
        self.largest = 0  # bytes of the largest entry so far, with its raw chunk while it is built

    @staticmethod
    def _size(e: dict) -> int:
        raw = e["raw"].nbytes if e.get("raw") is not None and e["raw"] is not e["pyr"][0] else 0
        return raw + sum(a.nbytes for part in (e["pyr"], e.get("nan") or ()) for a in part)

    def get_many(self, ks, *, nan: bool = False) -> list[dict]:
        """Per chunk: {"shape", "pyr": block pyramid, and with ``nan`` "nan": NaN pyramid}."""
        missing = [k for k in ks if k not in self.entries]
        if missing:
            # make room first: the budget holds while the new chunks are read and their pyramids built
            self._evict(keep=set(ks), extra=len(missing) * self.largest)
            arrays = self.compute([self.blocks[k // self.nbx, k % self.nbx] for k in missing])
            self.loads += len(missing)
            for k, a in zip(missing, arrays):
                a = np.ascontiguousarray(a)
                # the raw chunk is kept only for a NaN pyramid, which only chunks with NaN need
                self.entries[k] = {"shape": a.shape, "pyr": _search_pyramid(a, bool(self.has_nan[k])),
                                   "raw": a if self.has_nan[k] else None}
                self.largest = max(self.largest, self._size(self.entries[k]) + a.nbytes)
        out = []
        for k in ks:
            e = self.entries.pop(k)
            self.entries[k] = e  # most recent last
            if nan and "nan" not in e:
                e["nan"] = _mk.nan_pyramid(e["raw"])
                e["raw"] = None
            out.append(e)
        self._evict(keep=set(ks))
        return out

    def _evict(self, keep: set, extra: int = 0) -> None:
        """Drop the least recently used chunks not in ``keep`` until ``extra`` more bytes fit."""
        total = sum(self._size(e) for e in self.entries.values())
        for k in [k for k in self.entries if k not in keep]:
            if total + extra <= self.budget:
                break
            total -= self._size(self.entries.pop(k))


def _search_pyramid(block: np.ndarray, has_nan: bool) -> tuple:
    """(level 0, pyramid...) for :func:`~orokit.metrics._kernels.nearest_query`: a chunk without NaN
    is its own level 0 (no copy, in its own dtype, as the in-memory search does)."""
    if has_nan:
        return _mk.block_pyramid(block)
    return (block, *_mk.build_pyramid(block))


def chunk_isolation(core: np.ndarray, row0: int, col0: int, shape: tuple[int, int], keys: np.ndarray,
                    metric: KernelMetric) -> dict[str, np.ndarray]:
    """Isolation of candidate peaks (global flat ``keys``) that their own chunk settles.

    Run inside the tile task while the chunk is in memory: a peak is *resolved* when the
    nearest higher cell found in the chunk is closer (with the geodesic slack) than any
    cell outside the chunk. Returns the resolved peaks' ``key``, ``best`` (search
    distance), ``cand`` (global candidate cells, -1 padded) and ``nan`` (distance to the
    nearest NaN cell of the chunk, inf beyond ``best``).
    """
    H, W = shape
    h, w = core.shape
    rows = keys // W - row0
    cols = keys % W - col0
    pz = core[rows, cols].astype(np.float64)
    args = metric.args(row0)
    inf = np.full(keys.size, np.inf)
    has_nan = bool(np.isnan(core).any())
    best, cand = _mk.nearest_query(*_search_pyramid(core, has_nan), rows, cols, pz, inf, *args, metric.slack,
                                   metric.ncand)
    exterior = _mk.outside_distance(rows, cols, h, w, *args)
    ok = best * (1.0 + metric.slack) < exterior
    if has_nan:
        nan = _mk.nearest_nan_query(*_mk.nan_pyramid(core), rows[ok], cols[ok], best[ok], *args)
    else:
        nan = np.full(int(ok.sum()), np.inf)
    c = cand[ok]
    # candidates fill each row from the left: keep only the columns some peak uses (one or two
    # on a projected grid instead of ncand), this travels with the summaries until the end
    c = c[:, :int((c >= 0).sum(axis=1).max(initial=0))]
    gc = np.where(c >= 0, (row0 + c // w) * W + col0 + c % w, -1)
    return {"key": keys[ok], "best": best[ok], "cand": gc, "nan": nan}


def _hilbert_rank(nby: int, nbx: int) -> np.ndarray:
    """Rank of each chunk (raster order index) along a Hilbert curve over the chunk grid."""
    side = 1
    while side < max(nby, nbx):
        side *= 2
    i, j = np.divmod(np.arange(nby * nbx, dtype=np.int64), nbx)
    x, y, d = j.copy(), i.copy(), np.zeros(i.size, np.int64)
    s = side // 2
    while s > 0:
        rx = (x & s) > 0
        ry = (y & s) > 0
        d += s * s * ((3 * rx) ^ ry)
        # rotate the quadrant
        flip = ~ry & rx
        x = np.where(flip, s - 1 - x, x)
        y = np.where(flip, s - 1 - y, y)
        swap = ~ry
        x, y = np.where(swap, y, x), np.where(swap, x, y)
        s //= 2
    return d


def block_stats(block: np.ndarray) -> tuple[float, float]:
    """Maximum of a chunk (-inf when all NaN) and 1.0 if it holds a NaN."""
    valid = ~np.isnan(block)
    return (float(block[valid].max()) if valid.any() else -np.inf), float((~valid).any())


class SettledIsolation:
    """Isolation that the chunks settled (:func:`chunk_isolation`'s arrays ``key``, ``best``, ``cand``,
    ``nan``), read by bands of raster rows: the search reads the keys of one band at a time, the
    finish one band's arrays, so no array of every settled peak is held (~40 bytes per settled peak).

    ``bands`` lists each band's rows as (first, end); ``read(band, names)`` returns that band's
    arrays (``names``, or all four; a band's cells are all in its rows); ``close`` (optional) lets the
    source go (e.g. removes its spill files).
    """

    def __init__(self, bands: list[tuple[int, int]], read: Callable[[int, tuple[str, ...] | None], dict],
                 close: Callable[[], None] | None = None):
        self.bands = bands
        self._read = read
        self._close = close

    def read(self, band: int, names: tuple[str, ...] | None = None) -> dict[str, np.ndarray]:
        """The arrays of band ``band`` (all four, or ``names``)."""
        return self._read(band, names)

    def close(self) -> None:
        """Let the source go (its files are removed); later reads fail."""
        if self._close is not None:
            self._close()

    @classmethod
    def of(cls, arrays: dict[str, np.ndarray], row_bounds: np.ndarray, width: int) -> SettledIsolation:
        """The settled isolation ``arrays`` (in memory) by the bands ``row_bounds`` (row edges)."""
        bands = [(int(a), int(b)) for a, b in zip(row_bounds[:-1], row_bounds[1:])]

        def read(band: int, names: tuple[str, ...] | None) -> dict:
            r0, r1 = bands[band]
            key = arrays["key"]
            sel = np.flatnonzero((key >= r0 * width) & (key < r1 * width))
            return {f: arrays[f][sel] for f in (names or tuple(arrays))}
        return cls(bands, read)


def tiled_isolation(data, rows, cols, pz, *, transform, crs, compute=None, chunk_stats=None,
                    known: dict[str, np.ndarray] | SettledIsolation | None = None,
                    release_known: bool = False) -> pd.DataFrame:
    """Isolation of peaks at (rows, cols) with elevations pz on a dask array.

    Same result as :func:`orokit.metrics.isolation.isolation` on the whole array.
    ``compute`` is a callable that computes a list of dask objects (defaults to
    ``dask.compute``), so a distributed client can be used. ``chunk_stats`` (nby, nbx, 2)
    holds each chunk's maximum and NaN flag when already known (the tiled engine
    computes them while reading the chunks). ``known`` holds the peaks already settled
    inside their own chunk by :func:`chunk_isolation` (only the others are searched): a dict
    of its arrays, or a :class:`SettledIsolation` read band by band. With ``release_known`` the
    dict is emptied (the source closed) once read.

    Memory: only the searched peaks (those ``known`` does not settle: a few percent of them on
    real terrain) have search state; the settled ones are read one band of rows at a time, twice
    (their keys to find the searched peaks, then their arrays as the table is finished by bands).
    """
    import dask

    compute = compute or (lambda objs: dask.compute(*objs))
    metric = KernelMetric.from_grid(transform, crs)
    H, W = data.shape
    # per-peak arrays in the narrowest exact types (int32 places while they fit, the elevations in
    # their own float type)
    index = np.int32 if max(H, W, np.asarray(rows).size) < 2**31 else np.int64
    rows = np.asarray(rows).astype(index, copy=False)
    cols = np.asarray(cols).astype(index, copy=False)
    pz = np.asarray(pz)
    if pz.dtype not in (np.float32, np.float64):
        pz = pz.astype(np.float64)
    rb = np.concatenate([[0], np.cumsum(data.chunks[0])])
    cb = np.concatenate([[0], np.cumsum(data.chunks[1])])
    nby, nbx = len(rb) - 1, len(cb) - 1
    blocks = data.to_delayed()
    if chunk_stats is None:
        (chunk_stats,) = compute([dask.delayed(np.array)(
            [[dask.delayed(block_stats)(blocks[i, j]) for j in range(nbx)] for i in range(nby)])])
    chunk_stats = np.asarray(chunk_stats, dtype=float).reshape(nby * nbx, 2)
    cmax = chunk_stats[:, 0]
    cnan = chunk_stats[:, 1] > 0.5
    n = rows.size
    given = known
    settled = None
    if isinstance(known, SettledIsolation):
        settled = known
    elif known is not None and known["key"].size:
        settled = SettledIsolation.of(known, rb, W)
    bands = settled.bands if settled is not None else [(int(a), int(b)) for a, b in zip(rb[:-1], rb[1:])]
    peaks = _PeaksByRows(rows, cols, W)
    # the searched peaks: those no chunk settled (one band of settled keys in memory at a time)
    todo = np.ones(n, bool)
    if settled is not None:
        for b, (r0, r1) in enumerate(bands):
            members = peaks.members(r0, r1)
            at = peaks.find(settled.read(b, ("key",))["key"], members)
            todo[members[at[at >= 0]]] = False
            del members, at
    searched = np.flatnonzero(todo).astype(index, copy=False)
    del todo
    n_searched = searched.size
    # search state of the searched peaks only, by their position in ``searched``
    rs, cs, zs = rows[searched], cols[searched], pz[searched]
    best = np.full(n_searched, np.inf)
    edge = _outside(rs, cs, H, W, metric)
    cand = np.full((n_searched, metric.ncand), -1, np.int64)
    ncand = np.zeros(n_searched, np.int64)
    cache = _BlockCache(blocks, nbx, compute, cnan)
    # the searched peaks grouped by their own chunk, chunks along a Hilbert curve: the chunks
    # around the current one were mostly visited just before and are still in the cache
    # (in raster order a row of chunks is longer than the cache, so each chunk was read
    # again for the row above and the row below: 740 loads for 256 chunks at 1 G cells)
    curve = _hilbert_rank(nby, nbx)
    home = curve[(np.searchsorted(rb, rs, side="right") - 1) * nbx + np.searchsorted(cb, cs, side="right") - 1]
    order = np.lexsort((cs, rs, home))
    bounds = np.flatnonzero(np.diff(np.sort(home))) + 1
    del home
    slack = 1.0 + metric.slack
    batch = max(64, min(_BATCH, _BOUNDS_CELLS // (nby * nbx)))
    for group in np.split(order, bounds):
        for start in range(0, group.size, batch):
            idx = group[start:start + batch]
            lb = _chunk_bounds(rs[idx], cs[idx], rb, cb, metric)
            lb_nan = np.where(cnan[None, :], lb, np.inf)
            lb = np.where(cmax[None, :] > zs[idx, None], lb, np.inf)
            _visit(lb, idx, cache, rb, cb, nbx, metric, best, cand, ncand, zs, rs, cs, W, slack)
            # nearest NaN cell, only where it could be closer than the edge and the target
            _visit_nan(lb_nan, idx, cache, rb, cb, nbx, metric, best, edge, rs, cs)
    logger.info("isolation of %d peaks (%d settled in their chunk): %d chunk loads for %d chunks",
                n, n - n_searched, cache.loads, nby * nbx)
    del cache, order, bounds, rs, cs, zs
    release_free_heap()  # the chunks and pyramids the search read
    # the table finished by bands of rows: each band's settled peaks read again, its searched peaks'
    # state gathered, the nearest candidate chosen by blocks of peaks (each peak's choice is its own)
    out = {"isolation": np.empty(n), "isolation_row": np.empty(n, np.int64), "isolation_col": np.empty(n, np.int64),
           "isolation_exact": np.empty(n, bool)}
    for b, (r0, r1) in enumerate(bands):
        members = peaks.members(r0, r1)
        k = members.size
        if not k:
            continue
        r, c = rows[members].astype(np.int64), cols[members].astype(np.int64)
        bb = np.full(k, np.inf)
        ee = _outside(r, c, H, W, metric)
        pos = np.minimum(np.searchsorted(searched, members), max(n_searched - 1, 0))
        mine = np.flatnonzero(searched[pos] == members) if n_searched else np.empty(0, np.int64)
        pos = pos[mine]
        bb[mine], ee[mine] = best[pos], edge[pos]
        width = int(ncand[pos].max(initial=0))
        kc = None
        if settled is not None:
            part = settled.read(b)
            at = peaks.find(part["key"], members)
            hit = np.flatnonzero(at >= 0)
            at = at[hit]
            bb[at] = part["best"][hit]
            ee[at] = np.minimum(ee[at], part["nan"][hit])
            kc = part["cand"][hit]
            del part, hit
            width = max(width, int((kc >= 0).sum(axis=1).max(initial=0)))
        block = np.full((k, width), -1, np.int64)
        block[mine] = cand[pos, :width]
        if kc is not None:
            m = min(width, kc.shape[1])
            block[at, :m] = kc[:, :m]
        del kc, mine, pos
        for s0 in range(0, k, _FINISH_ROWS):
            s1 = min(k, s0 + _FINISH_ROWS)
            done = finish_isolation(metric, r[s0:s1], c[s0:s1], bb[s0:s1], block[s0:s1], W, ee[s0:s1])
            for f in out:
                out[f][members[s0:s1]] = done[f].to_numpy()
            del done
        del members, r, c, bb, ee, block
    if release_known:
        if isinstance(given, SettledIsolation):
            given.close()
        elif given is not None:
            given.clear()
    return pd.DataFrame(out, copy=False)


def _outside(rows: np.ndarray, cols: np.ndarray, H: int, W: int, metric: KernelMetric) -> np.ndarray:
    """Distance from each cell to the nearest cell outside the raster, by blocks (the kernel's int64 places)."""
    edge = np.empty(rows.size)
    for s0 in range(0, rows.size, _FINISH_ROWS):
        s1 = min(rows.size, s0 + _FINISH_ROWS)
        edge[s0:s1] = _mk.outside_distance(rows[s0:s1].astype(np.int64), cols[s0:s1].astype(np.int64), H, W,
                                           *metric.args())
    return edge


class _PeaksByRows:
    """The peaks of a band of rows, in raster order, and the rows of cells among them.

    Peaks in raster order (the engine's) are ranges of the arrays as they are; others are
    ranked once (an int64 order, 8 bytes per peak).
    """

    def __init__(self, rows: np.ndarray, cols: np.ndarray, width: int):
        self.rows, self.cols, self.width = rows, cols, width
        self.order: np.ndarray | None = None
        ordered = True
        for s0 in range(0, max(rows.size - 1, 0), _FINISH_ROWS):  # by blocks: no whole int64 cells
            s1 = min(rows.size, s0 + _FINISH_ROWS + 1)
            cell = rows[s0:s1].astype(np.int64) * width + cols[s0:s1]
            if not bool((cell[1:] > cell[:-1]).all()):
                ordered = False
                break
        if not ordered:
            self.order = np.argsort(rows.astype(np.int64) * width + cols, kind="stable")
        self.sorted_rows = rows if self.order is None else rows[self.order]

    def members(self, r0: int, r1: int) -> np.ndarray:
        """Indices of the peaks in rows ``r0`` to ``r1`` (excluded), in raster order."""
        p0, p1 = np.searchsorted(self.sorted_rows, [r0, r1], side="left")
        if self.order is None:
            return np.arange(p0, p1, dtype=np.int64)
        return self.order[p0:p1]

    def find(self, keys: np.ndarray, members: np.ndarray) -> np.ndarray:
        """Position of each flat cell ``keys`` in ``members`` (raster order), -1 where it is no peak."""
        cell = self.rows[members].astype(np.int64) * self.width + self.cols[members]
        if not cell.size:
            return np.full(keys.size, -1, np.int64)
        at = np.minimum(np.searchsorted(cell, keys), cell.size - 1)
        at[cell[at] != keys] = -1
        return at


def cell_places(cell: np.ndarray, width: int) -> tuple[np.ndarray, np.ndarray]:
    """Row and column of flat cells (``cell // width``, ``cell % width``), int32 while they fit, made
    by blocks (no whole int64 arrays beside them: 8 bytes per cell instead of 16, and no transient)."""
    index = np.int32 if max(int(width), int(cell.max(initial=0)) // max(int(width), 1) + 1) < 2**31 else np.int64
    rows, cols = np.empty(cell.size, index), np.empty(cell.size, index)
    for s0 in range(0, cell.size, _FINISH_ROWS):
        r, c = np.divmod(cell[s0:s0 + _FINISH_ROWS], width)
        rows[s0:s0 + r.size], cols[s0:s0 + r.size] = r, c
    return rows, cols


def _visit(lb, idx, cache, rb, cb, nbx, metric, best, cand, ncand, pz, rows, cols, W, slack):
    while True:
        nxt = np.argmin(lb, axis=1)
        val = lb[np.arange(idx.size), nxt]
        active = np.isfinite(val) & (val <= best[idx] * slack)
        if not active.any():
            return
        chunks = np.unique(nxt[active])
        for k, block in zip(chunks, cache.get_many(list(chunks))):
            sel = np.flatnonzero(active & (nxt == k))
            p = idx[sel]
            i, j = k // nbx, k % nbx
            r0, c0 = rb[i], cb[j]
            b, cl = _mk.nearest_query(
                *block["pyr"], rows[p] - r0, cols[p] - c0, pz[p].astype(np.float64), best[p] * slack,
                *metric.args(r0), metric.slack, metric.ncand,
            )
            bw = block["shape"][1]
            # append each peak's candidates (a prefix of its row of cl) while its row of cand has room
            take = np.minimum((cl >= 0).sum(axis=1), cand.shape[1] - ncand[p])
            t, j = np.nonzero(np.arange(cl.shape[1])[None, :] < take[:, None])
            found = cl[t, j]
            cand[p[t], ncand[p[t]] + j] = (r0 + found // bw) * W + c0 + found % bw
            ncand[p] += take
            best[p] = np.minimum(best[p], b)
            lb[sel, k] = np.inf


def _visit_nan(lb, idx, cache, rb, cb, nbx, metric, best, edge, rows, cols):
    while True:
        nxt = np.argmin(lb, axis=1)
        val = lb[np.arange(idx.size), nxt]
        cut = np.minimum(edge[idx], best[idx])
        # a NaN cell as far as the target makes the isolation inexact (dist < edge): ties are visited
        active = np.isfinite(val) & (val <= cut)
        if not active.any():
            return
        chunks = np.unique(nxt[active])
        for k, block in zip(chunks, cache.get_many(list(chunks), nan=True)):
            sel = np.flatnonzero(active & (nxt == k))
            p = idx[sel]
            r0, c0 = rb[k // nbx], cb[k % nbx]
            d = _mk.nearest_nan_query(
                *block["nan"], rows[p] - r0, cols[p] - c0, np.minimum(edge[p], best[p]), *metric.args(r0),
            )
            edge[p] = np.minimum(edge[p], d)
            lb[sel, k] = np.inf
