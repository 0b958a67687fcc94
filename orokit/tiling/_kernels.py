"""Numba kernels of the tiled engine (one chunk with a one-cell halo).

numba for the same reason as :mod:`orokit.topology._kernels`: per-cell neighbour
sweeps with data-dependent branches.
"""
from __future__ import annotations

import numpy as np
from numba import njit

_NEIGHBOURS_8 = ((-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1))


@njit(cache=True, nogil=True)
def steepest_ascent_halo(zh):
    """Steepest ascent inside a chunk given with a one-cell halo.

    Pointers only follow cells of the chunk (the core ``zh[1:-1, 1:-1]``), so basins
    are chunk-local; the halo is only read to flag "border" cells: cells next to a NaN
    cell, where the halo is NaN outside the raster (so raster-edge cells are border).
    Tie-break keys are chunk-local raster order, which orders cells exactly as the
    global raster order does.
    """
    Hh, Wh = zh.shape
    h = Hh - 2
    w = Wh - 2
    n = h * w
    ptr = np.empty(n, np.int64)
    border = np.zeros(n, np.bool_)
    for r in range(h):
        for c in range(w):
            i = r * w + c
            zi = zh[r + 1, c + 1]
            if zi != zi:
                ptr[i] = -1
                continue
            best = i
            bz = zi
            isb = False
            for d in _NEIGHBOURS_8:
                rr = r + d[0]
                cc = c + d[1]
                zn = zh[rr + 1, cc + 1]
                if zn != zn:
                    isb = True
                    continue
                if rr < 0 or rr >= h or cc < 0 or cc >= w:
                    continue
                j = rr * w + cc
                if zn > bz or (zn == bz and j < best):
                    best = j
                    bz = zn
            ptr[i] = best
            border[i] = isb
    return ptr, border
