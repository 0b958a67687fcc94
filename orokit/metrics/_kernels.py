"""Numba kernels for isolation (nearest strictly higher cell).

A pyramid of block maxima (each level halves the raster) prunes a best-first search:
blocks are visited by increasing lower bound of their distance to the peak and a block
whose maximum is not above the peak's elevation is skipped. The first single cell
popped from the queue is the nearest higher cell. numba is needed because the search
is a priority-queue traversal that numpy cannot vectorise.

Two metrics: Euclidean on a grid of ``dx`` x ``dy`` metres (projected or local CRS),
and great-circle distance on a sphere for geographic grids. For geographic grids the
kernel returns every candidate within ``slack`` (relative) of the spherical optimum,
so the caller can pick the exact ellipsoidal (WGS84) geodesic minimum among them.
"""
from __future__ import annotations

import heapq
import math

import numpy as np
from numba import njit, prange

EARTH_RADIUS_M = 6371008.8


@njit(cache=True, nogil=True)
def _pyramid_layout(H, W):
    """Heights, widths and offsets (in ``values``) of the levels of an H x W pyramid."""
    nlev = 1
    h, w = H, W
    while h > 1 or w > 1:
        h, w = (h + 1) // 2, (w + 1) // 2
        nlev += 1
    hs = np.empty(nlev, np.int64)
    ws = np.empty(nlev, np.int64)
    offs = np.zeros(nlev + 1, np.int64)
    hs[0], ws[0] = H, W
    for k in range(1, nlev):
        hs[k] = (hs[k - 1] + 1) // 2
        ws[k] = (ws[k - 1] + 1) // 2
        offs[k + 1] = offs[k] + hs[k] * ws[k]
    return hs, ws, offs


@njit(cache=True, nogil=True)
def _halve(src, dst):
    """``dst``: maxima of the 2 x 2 blocks of ``src`` (cut at its edges).

    Each block keeps its first cell unless a later one (raster order) is larger; at the
    edges the last row/column is read twice, which changes nothing. Straight-line code
    over the two arrays (no per-cell level lookup): ~20x faster than a generic loop.
    """
    H, W = src.shape
    h, w = dst.shape
    for r in range(h):
        a = 2 * r
        b = min(a + 1, H - 1)
        for c in range(w):
            x = 2 * c
            y = min(x + 1, W - 1)
            m = src[a, x]
            v = src[a, y]
            if v > m:
                m = v
            v = src[b, x]
            if v > m:
                m = v
            v = src[b, y]
            if v > m:
                m = v
            dst[r, c] = m


@njit(cache=True, nogil=True)
def build_pyramid(level0):
    """Block-maximum pyramid stored flat. Returns (values, offsets, heights, widths).

    Level 0 is ``level0`` itself and is not copied: ``values`` holds levels 1.. (level
    k at ``offsets[k]``; ``offsets[0] == offsets[1] == 0``); read a level with :func:`_level_value`.
    """
    hs, ws, offs = _pyramid_layout(level0.shape[0], level0.shape[1])
    vals = np.empty(offs[hs.size], level0.dtype)
    if hs.size > 1:
        _halve(level0, vals[:offs[2]].reshape(hs[1], ws[1]))
    for k in range(2, hs.size):
        _halve(vals[offs[k - 1]:offs[k]].reshape(hs[k - 1], ws[k - 1]), vals[offs[k]:offs[k + 1]].reshape(hs[k], ws[k]))
    return vals, offs, hs, ws


@njit(cache=True, nogil=True, inline="always")
def _level_value(level0, vals, offs, ws, k, r, c):
    """Cell (r, c) of level k of a pyramid from :func:`build_pyramid` (level 0 = ``level0``)."""
    if k == 0:
        return level0[r, c]
    return vals[offs[k] + r * ws[k] + c]


@njit(cache=True, nogil=True)
def _gap(p, lo, hi):
    if p < lo:
        return lo - p
    if p > hi:
        return p - hi
    return 0


@njit(cache=True, nogil=True)
def _lower_bound(pr, pc, r0, r1, c0, c1, geo, dx, dy, lat0, row0, dlat, dlon):
    """Lower bound of the distance from cell (pr, pc) to any cell of the block."""
    gr = _gap(pr, r0, r1)
    gc = _gap(pc, c0, c1)
    if not geo:
        return math.hypot(gr * dy, gc * dx)
    # sphere: hav(d) >= hav(dphi) + cos^2(phi_max) hav(dlambda)
    dphi = gr * abs(dlat)
    dlam = gc * abs(dlon)
    la = abs(lat0 + (row0 + pr + 0.5) * dlat)
    lb = abs(lat0 + (row0 + r0 + 0.5) * dlat)
    lc = abs(lat0 + (row0 + r1 + 0.5) * dlat)
    phimax = max(la, max(lb, lc))
    cm = math.cos(min(phimax, math.pi / 2))
    s = math.sin(dphi / 2) ** 2 + cm * cm * math.sin(dlam / 2) ** 2
    return 2 * EARTH_RADIUS_M * math.asin(min(1.0, math.sqrt(s)))


@njit(cache=True, nogil=True)
def _cell_distance(pr, pc, r, c, geo, dx, dy, lat0, row0, dlat, dlon):
    if not geo:
        return math.hypot((r - pr) * dy, (c - pc) * dx)
    p1 = lat0 + (row0 + pr + 0.5) * dlat
    p2 = lat0 + (row0 + r + 0.5) * dlat
    dl = (c - pc) * dlon
    s = math.sin((p2 - p1) / 2) ** 2 + math.cos(p1) * math.cos(p2) * math.sin(dl / 2) ** 2
    return 2 * EARTH_RADIUS_M * math.asin(min(1.0, math.sqrt(s)))


@njit(cache=True, nogil=True)
def _nearest(level0, vals, offs, hs, ws, pr, pc, thresh, cutoff, geo, dx, dy, lat0, row0, dlat, dlon, slack, cand,
             ncand_max):
    """Best-first search of the nearest cell with value > thresh, up to ``cutoff``.

    Fills ``cand`` with (flat cell) candidates within ``slack`` of the optimum and
    returns (best distance or inf, number of candidates).
    """
    nlev = hs.size
    top = nlev - 1
    heap = [(0.0, np.int64(0), np.int64(0), np.int64(0))]
    heap.pop()
    W0 = ws[0]
    H0 = hs[0]
    for r in range(hs[top]):
        for c in range(ws[top]):
            size = 1 << top
            lb = _lower_bound(pr, pc, r * size, min((r + 1) * size, H0) - 1, c * size,
                              min((c + 1) * size, W0) - 1, geo, dx, dy, lat0, row0, dlat, dlon)
            heapq.heappush(heap, (lb, np.int64(top), np.int64(r), np.int64(c)))
    best = np.inf
    n = 0
    while len(heap) > 0:
        lb, k, r, c = heapq.heappop(heap)
        if lb > cutoff or lb > best * (1.0 + slack):
            break
        if _level_value(level0, vals, offs, ws, k, r, c) <= thresh:
            continue
        if k == 0:
            d = lb
            if d < best:
                best = d
            if n < ncand_max:
                cand[n] = r * W0 + c
                n += 1
            continue
        size = 1 << (k - 1)
        for dr in range(2):
            for dc in range(2):
                rr = 2 * r + dr
                cc = 2 * c + dc
                if rr < hs[k - 1] and cc < ws[k - 1]:
                    if k - 1 == 0:
                        lbc = _cell_distance(pr, pc, rr, cc, geo, dx, dy, lat0, row0, dlat, dlon)
                    else:
                        lbc = _lower_bound(pr, pc, rr * size, min((rr + 1) * size, H0) - 1, cc * size,
                                           min((cc + 1) * size, W0) - 1, geo, dx, dy, lat0, row0, dlat, dlon)
                    heapq.heappush(heap, (lbc, np.int64(k - 1), rr, cc))
    # keep only candidates within slack of the best
    m = 0
    for i in range(n):
        rr = cand[i] // W0
        cc = cand[i] % W0
        if _cell_distance(pr, pc, rr, cc, geo, dx, dy, lat0, row0, dlat, dlon) <= best * (1.0 + slack):
            cand[m] = cand[i]
            m += 1
    return best, m


@njit(cache=True, nogil=True)
def _window_scan(block, pr, pc, thresh, cutoff, geo, dx, dy, lat0, row0, dlat, dlon, radius, buf):
    """Exact answer from the cells within ``radius`` cells of (pr, pc), if it is there.

    Returns (best, n_candidates); best = inf when the window cannot prove the answer
    (no higher cell inside the disc that the window fully contains).
    """
    H, W = block.shape
    best = np.inf
    r0 = max(pr - radius, 0)
    r1 = min(pr + radius, H - 1)
    c0 = max(pc - radius, 0)
    c1 = min(pc + radius, W - 1)
    for r in range(r0, r1 + 1):
        for c in range(c0, c1 + 1):
            v = block[r, c]
            if v > thresh:
                d = math.hypot((r - pr) * dy, (c - pc) * dx)
                if d < best:
                    best = d
    # the window holds every cell closer than (radius + 1) cells of the smaller size
    if not best < (radius + 1) * min(dx, dy) or best > cutoff:
        return np.inf, 0
    n = 0
    for r in range(r0, r1 + 1):
        for c in range(c0, c1 + 1):
            if block[r, c] > thresh and n < buf.size:
                if math.hypot((r - pr) * dy, (c - pc) * dx) <= best:
                    buf[n] = r * W + c
                    n += 1
    return best, n


@njit(cache=True, nogil=True)
def block_pyramid(block):
    """(zz, pyramid...) of a block: NaN replaced by -inf (in the block's dtype: a float32 block
    stays float32, half the memory of a float64 copy), and its block-maximum pyramid."""
    zz = block.copy()
    flat = zz.reshape(-1)
    for i in range(flat.size):
        if np.isnan(flat[i]):
            flat[i] = -np.inf
    vals, offs, hs, ws = build_pyramid(zz)
    return zz, vals, offs, hs, ws


@njit(cache=True, nogil=True)
def nan_pyramid(block):
    """(mask, pyramid...) of "holds a NaN" (1.0) of a block."""
    mask = np.isnan(block).astype(np.float32)
    vals, offs, hs, ws = build_pyramid(mask)
    return mask, vals, offs, hs, ws


@njit(cache=True, nogil=True, parallel=True)
def nearest_query(zz, vals, offs, hs, ws, prow, pcol, pz, cutoff, geo, dx, dy, lat0, row0, dlat, dlon, slack, ncand):
    """Nearest cell strictly higher than ``pz`` for every query, on a block's pyramid.

    Query cells ``(prow, pcol)`` are relative to the block's first cell and may lie
    outside it (chunked isolation). ``lat0`` is the latitude (radians) of the raster's
    top edge for geographic grids and ``row0`` the block's first row in the raster (the
    latitude of a cell is computed from its raster row, so a chunk and the whole raster
    give bit-identical distances). Searches stop at ``cutoff`` (per query).
    Returns ``best`` (distance, inf if none within the cutoff) and ``cand`` (n x
    ncand flat indices in the block, -1 padded: every cell within ``slack`` of the
    best, for an exact check by the caller). Queries run in parallel threads.
    """
    H, W = zz.shape
    n = prow.size
    best = np.full(n, np.inf)
    cand = np.full((n, ncand), -1, np.int64)
    for i in prange(n):
        buf = np.empty(ncand, np.int64)
        b = np.inf
        m = 0
        inside = prow[i] >= 0 and prow[i] < H and pcol[i] >= 0 and pcol[i] < W
        if inside and not geo:
            # most peaks have higher ground a few cells away: a small window proves it
            b, m = _window_scan(zz, prow[i], pcol[i], pz[i], cutoff[i], geo, dx, dy, lat0, row0, dlat, dlon, 6, buf)
        if m == 0:
            b, m = _nearest(zz, vals, offs, hs, ws, prow[i], pcol[i], pz[i], cutoff[i], geo, dx, dy, lat0, row0, dlat,
                            dlon, slack, buf, ncand)
        best[i] = b
        for j in range(m):
            cand[i, j] = buf[j]
    return best, cand


@njit(cache=True, nogil=True)
def nearest_nan_query(mask, vals, offs, hs, ws, prow, pcol, cutoff, geo, dx, dy, lat0, row0, dlat, dlon):
    """Distance from each query cell to the nearest NaN cell (inf if none), on a NaN pyramid."""
    n = prow.size
    out = np.full(n, np.inf)
    if _level_value(mask, vals, offs, ws, hs.size - 1, 0, 0) < 0.5:
        return out
    buf = np.empty(1, np.int64)
    for i in range(n):
        d, _ = _nearest(mask, vals, offs, hs, ws, prow[i], pcol[i], 0.5, cutoff[i], geo, dx, dy, lat0, row0, dlat, dlon,
                        0.0, buf, 1)
        out[i] = d
    return out


def nearest_in_block(block, prow, pcol, pz, cutoff, geo, dx, dy, lat0, row0, dlat, dlon, slack, ncand):
    """:func:`nearest_query` on a block (pyramid built here)."""
    return nearest_query(*block_pyramid(block), prow, pcol, pz, cutoff, geo, dx, dy, lat0, row0, dlat, dlon, slack, ncand)


def nearest_nan_in_block(block, prow, pcol, cutoff, geo, dx, dy, lat0, row0, dlat, dlon):
    """:func:`nearest_nan_query` on a block (pyramid built here)."""
    return nearest_nan_query(*nan_pyramid(block), prow, pcol, cutoff, geo, dx, dy, lat0, row0, dlat, dlon)


@njit(cache=True, nogil=True)
def outside_distance(prow, pcol, H, W, geo, dx, dy, lat0, row0, dlat, dlon):
    """Distance from each cell to the nearest cell outside an H x W raster."""
    n = prow.size
    out = np.empty(n)
    for i in range(n):
        pr = prow[i]
        pc = pcol[i]
        out[i] = min(
            min(_cell_distance(pr, pc, -1, pc, geo, dx, dy, lat0, row0, dlat, dlon),
                _cell_distance(pr, pc, H, pc, geo, dx, dy, lat0, row0, dlat, dlon)),
            min(_cell_distance(pr, pc, pr, -1, geo, dx, dy, lat0, row0, dlat, dlon),
                _cell_distance(pr, pc, pr, W, geo, dx, dy, lat0, row0, dlat, dlon)),
        )
    return out
