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
