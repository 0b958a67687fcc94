"""Kernels of the in-memory engine's row strips (numba): basins and passes without a label per raster cell.

A strip is rows ``r0:r1`` of the whole raster ``z``; its cells' steepest-ascent pointers
read their neighbours in the whole raster (ties as in :mod:`orokit.topology._kernels`),
and a chain is followed inside the strip only. It ends at a *terminal*: a maximum in
the strip, or an *exit*, the first cell outside it (in row ``r0 - 1`` or ``r1``).
Terminal ids of a strip: its maxima ``0..m-1`` in raster order, then ``m + c`` for the
cell of row ``r0 - 1`` at column ``c`` and ``m + W + c`` for that of row ``r1``. The
caller resolves exits through the neighbouring strips' first and last rows
(``engine.saddle_graph``).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from orokit.topology._kernels import (_FORWARD_4, _NEIGHBOURS_8, _grow_pass_table, _insert, _unpack_pass_table, above,
                                      ascent_pointer, point_chain_at_end)


@njit(cache=True, nogil=True)
def strip_ascent(z, r0, r1, lab):
    """Terminal of every cell of rows ``r0:r1`` of ``z`` into ``lab`` (``(r1 - r0) * W``, int32 or int64).

    ``lab`` first holds pointers (strip-local cell) or the encoded terminal ``-2 - t``
    (maxima ``t < n``, exits ``n + c`` and ``n + W + c`` with ``n`` the strip's cells),
    then, chain by chain, the terminal id; -1 for NaN cells. Returns ``(m, max_cell)``:
    the number of maxima in the strip and their flat cells in the whole raster.
    """
    H, W = z.shape
    off = r0 * W
    n = (r1 - r0) * W
    cells = np.empty(1024, np.int64)
    m = 0
    for r in range(r0, r1):
        for c in range(W):
            i = r * W + c
            best = ascent_pointer(z, r, c)
            if best < 0:
                lab[i - off] = -1
                continue
            if best == i:
                if m == cells.size:
                    bigger = np.empty(cells.size * 2, np.int64)
                    bigger[:m] = cells[:m]
                    cells = bigger
                cells[m] = i
                lab[i - off] = -2 - m
                m += 1
            elif best < off:
                lab[i - off] = -2 - (n + best % W)
            elif best >= off + n:
                lab[i - off] = -2 - (n + W + best % W)
            else:
                lab[i - off] = best - off
    stack = np.empty(1024, np.int64)
    for i in range(n):
        if lab[i] >= 0:
            stack = point_chain_at_end(lab, i, stack)
    for i in range(n):
        v = lab[i]
        if v <= -2:
            t = -2 - v
            lab[i] = t if t < n else t - n + m
    return m, cells[:m].copy()


@njit(cache=True, nogil=True)
def strip_graph(z, lab, nterm, r0, r1):
    """Border maxima, minima and highest passes of the terminals of rows ``r0:r1`` (``lab`` of
    :func:`strip_ascent`), for the cell pairs with both cells in the strip (the pairs across a strip's
    last row are the caller's); each terminal pair keeps its highest pass, the lower cell of a pair. A border cell touches the
    raster's edge or a NaN cell (read in ``z``: outside the strip too). Returns
    ``(bmax, nmin, ea, eb, ec)`` over terminal ids, ``ec`` flat cells of the whole raster.
    """
    H, W = z.shape
    zf = z.ravel()
    off = r0 * W
    bmax = np.full(nterm, -np.inf)
    nmin = np.full(nterm, np.inf)
    size = 1024
    while size < 8 * nterm + 1024:
        size *= 2
    keys = np.full(size, -1, np.int64)
    vals = np.empty(size, lab.dtype)
    count = 0
    for r in range(r0, r1):
        for c in range(W):
            i = r * W + c
            la = lab[i - off]
            if la < 0:
                continue
            zi = zf[i]
            if zi < nmin[la]:
                nmin[la] = zi
            if zi > bmax[la]:
                isb = r == 0 or r == H - 1 or c == 0 or c == W - 1
                if not isb:
                    for d in _NEIGHBOURS_8:
                        zn = zf[(r + d[0]) * W + c + d[1]]
                        if zn != zn:
                            isb = True
                            break
                if isb:
                    bmax[la] = zi
            for d in _FORWARD_4:
                rr = r + d[0]
                cc = c + d[1]
                if rr >= r1 or cc < 0 or cc >= W:
                    continue
                j = rr * W + cc
                lb = lab[j - off]
                if lb < 0 or lb == la:
                    continue
                p = j if above(zi, i, zf[j], j) else i
                if la < lb:
                    key = la * np.int64(nterm) + lb
                else:
                    key = lb * np.int64(nterm) + la
                count += _insert(keys, vals, key, p, zf)
                if 2 * count > keys.size:
                    keys, vals = _grow_pass_table(keys, vals, zf)
    ea, eb, ec = _unpack_pass_table(keys, vals, count, nterm)
    return bmax, nmin, ea, eb, ec


@njit(cache=True, nogil=True)
def terminal_extremes(bmax, nmin, term, tmax, tmin):
    """``bmax[t] = max(bmax[t], tmax[i])`` and ``nmin[t] = min(nmin[t], tmin[i])`` for every ``t = term[i] >= 0``
    (``np.maximum.at`` / ``np.minimum.at`` over the terminals that reach a basin; NaN propagates as there)."""
    for i in range(term.size):
        t = term[i]
        if t < 0:
            continue
        v = tmax[i]
        b = bmax[t]
        if b == b and (v != v or v > b):
            bmax[t] = v
        v = tmin[i]
        b = nmin[t]
        if b == b and (v != v or v < b):
            nmin[t] = v


@njit(cache=True, nogil=True)
def _higher_pass(zf, c1, c2):
    """Whether pass cell ``c1`` comes before ``c2`` in ``np.lexsort((c, -zf[c]))``: higher first (NaN
    last), then the lower cell; False when both keys are equal."""
    z1 = zf[c1]
    z2 = zf[c2]
    if z1 != z1:
        if z2 == z2:
            return False
    elif z2 != z2 or z1 > z2:
        return True
    elif z1 < z2:
        return False
    return c1 < c2


@njit(cache=True, nogil=True)
def basin_pairs(a, b, c, zf, touched, n_max):
    """The saddle graph's edges from the strips' pairs ``(a, b)`` of basins with pass cell ``c``.

    Pairs within one basin are dropped; each edge is ``(min, max)`` of its basins. Of the edges
    of a basin pair, only the highest pass is kept (elevation ``zf[c]``, then the lower cell,
    then the first found), among the candidates: edges with a basin in ``touched`` (size
    ``n_max + 1``; basin -1 reads its last entry). Returns ``(lo, hi, c)`` in the input's order:
    the first of each pair in ``np.lexsort((c, -zf[c], key))`` over the candidates' pair keys.
    ``a``, ``b`` and ``c`` (int64) are overwritten (the edges are compacted in place; 8 bytes per
    candidate for the pairs' table, then the result's copies).
    """
    n = a.size
    nt = touched.size
    cnt = 0
    ncand = 0
    for i in range(n):  # in place: the j-th kept pair is written at j <= i
        x = a[i]
        y = b[i]
        if x == y:
            continue
        lo = min(x, y)
        hi = max(x, y)
        a[cnt] = lo
        b[cnt] = hi
        c[cnt] = c[i]
        if touched[lo if lo >= 0 else nt + lo] or touched[hi if hi >= 0 else nt + hi]:
            ncand += 1
        cnt += 1
    # the candidates' pairs in an open-addressing table (a slot holds the pair's best edge so far;
    # its key is read from the edge), in the input's order: a later edge of a pair replaces the
    # kept one only when its pass is higher
    bits = 1
    while (1 << bits) < 2 * ncand:
        bits += 1
    size = 1 << bits
    slot = np.full(size, -1, np.int64)
    mult = np.int64(max(n_max, 1))
    dup = np.zeros(cnt, np.bool_)
    for j in range(cnt):
        lo = a[j]
        hi = b[j]
        if not (touched[lo if lo >= 0 else nt + lo] or touched[hi if hi >= 0 else nt + hi]):
            continue
        key = lo * mult + hi
        h = np.int64((np.uint64(key) * np.uint64(0x9E3779B97F4A7C15)) >> np.uint64(64 - bits))  # Fibonacci hashing
        while slot[h] >= 0 and a[slot[h]] * mult + b[slot[h]] != key:
            h = (h + 1) & (size - 1)
        best = slot[h]
        if best < 0:
            slot[h] = j
        elif _higher_pass(zf, c[j], c[best]):
            dup[best] = True
            slot[h] = j
        else:
            dup[j] = True
    m = 0
    for j in range(cnt):
        if not dup[j]:
            a[m] = a[j]
            b[m] = b[j]
            c[m] = c[j]
            m += 1
    return a[:m].copy(), b[:m].copy(), c[:m].copy()
