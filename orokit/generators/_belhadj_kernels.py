"""Numba kernels of the Belhadj 2007 backend: midpoint displacement (MD) and its inverse (MDI).

Grids are square, ``N = 2^k + 1`` cells a side. A subdivision level of side ``L``
(``L = N - 1, ..., 2``, half ``h = L / 2``) creates the cells whose row and column are
multiples of ``h`` but not both of ``L``:

* diamond-square (``mode = 0``): sub-step 0 (diamond) creates the square centres
  (``i/h, j/h`` both odd) from the 4 corners at distance ``h*sqrt(2)``; sub-step 1 (square)
  creates the edge midpoints (one odd) from the 2-4 cells at distance ``h`` (corners and
  centres).
* triangle-edge (``mode = 1``): one sub-step creates the midpoints of the horizontal,
  vertical and (main) diagonal edges of the level-``L`` squares from the edge's 2 ends.

States: 0 NULL, 1 known (skeleton), 2 filled by MDI, 3 filled by MD.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

NULL, KNOWN, MDI, MD = 0, 1, 2, 3


@njit(cache=True)
def _parents(i, j, h, mode, n, pi, pj):
    """Parents of cell (i, j) created at half-step ``h``; returns (count, distance)."""
    a = (i // h) % 2
    b = (j // h) % 2
    k = 0
    if a == 1 and b == 1:
        if mode == 0:
            for di in (-h, h):
                for dj in (-h, h):
                    pi[k] = i + di
                    pj[k] = j + dj
                    k += 1
        else:
            pi[0] = i - h
            pj[0] = j - h
            pi[1] = i + h
            pj[1] = j + h
            k = 2
        return k, h * math.sqrt(2.0)
    if mode == 0:
        for di, dj in ((-h, 0), (h, 0), (0, -h), (0, h)):
            r = i + di
            c = j + dj
            if 0 <= r < n and 0 <= c < n:
                pi[k] = r
                pj[k] = c
                k += 1
    elif a == 1:  # vertical edge: ends above and below
        pi[0] = i - h
        pj[0] = j
        pi[1] = i + h
        pj[1] = j
        k = 2
    else:  # horizontal edge
        pi[0] = i
        pj[0] = j - h
        pi[1] = i
        pj[1] = j + h
        k = 2
    return k, float(h)


@njit(cache=True)
def _in_substep(i, j, h, mode, sub):
    """Is cell (i, j) (multiples of h) created by sub-step ``sub`` of half-step h?"""
    a = (i // h) % 2
    b = (j // h) % 2
    if a == 0 and b == 0:
        return False
    if mode == 1:
        return True
    if sub == 0:
        return a == 1 and b == 1
    return a + b == 1


@njit(cache=True)
def parent_lists(n, mode):
    """Every cell's parents as CSR arrays ``(start, pi, pj)`` (for tests and figures)."""
    start = np.zeros(n * n + 1, np.int64)
    ti = np.empty(n * n * 4, np.int64)
    tj = np.empty(n * n * 4, np.int64)
    pi = np.empty(4, np.int64)
    pj = np.empty(4, np.int64)
    m = 0
    for i in range(n):
        for j in range(n):
            idx = i * n + j
            if not ((i == 0 or i == n - 1) and (j == 0 or j == n - 1)):
                h = 1
                while (i % (2 * h) == 0) and (j % (2 * h) == 0):
                    h *= 2
                k, _ = _parents(i, j, h, mode, n, pi, pj)
                for q in range(k):
                    ti[m] = pi[q]
                    tj[m] = pj[q]
                    m += 1
            start[idx + 1] = m
    return start, ti[:m], tj[:m]


@njit(cache=True)
def mdi(z, state, u, scale, hurst, mode):
    """Inverse midpoint displacement (in place), finest level first.

    At each sub-step, from the finest up: every NULL cell of the sub-step that has known
    children gets ``mean(children) + scale * mean(distance)^hurst * u`` (state 2); then
    every non-NULL cell of the sub-step adds its elevation and distance to its NULL
    parents' lists. Corners last. Returns the number of cells filled.
    """
    n = z.shape[0]
    acc_v = np.zeros((n, n))
    acc_d = np.zeros((n, n))
    acc_n = np.zeros((n, n), np.int32)
    pi = np.empty(4, np.int64)
    pj = np.empty(4, np.int64)
    filled = 0
    h = 1
    while h < n - 1:
        for s in range(2):
            sub = 1 - s if mode == 0 else 0
            if mode == 1 and s == 1:
                break
            for i in range(0, n, h):
                for j in range(0, n, h):
                    if not _in_substep(i, j, h, mode, sub):
                        continue
                    if state[i, j] == NULL and acc_n[i, j] > 0:
                        c = acc_n[i, j]
                        z[i, j] = acc_v[i, j] / c + scale * (acc_d[i, j] / c) ** hurst * u[i, j]
                        state[i, j] = MDI
                        filled += 1
            for i in range(0, n, h):
                for j in range(0, n, h):
                    if state[i, j] == NULL or not _in_substep(i, j, h, mode, sub):
                        continue
                    k, d = _parents(i, j, h, mode, n, pi, pj)
                    for q in range(k):
                        r = pi[q]
                        c = pj[q]
                        if state[r, c] == NULL:
                            acc_v[r, c] += z[i, j]
                            acc_d[r, c] += d
                            acc_n[r, c] += 1
        h *= 2
    for i in (0, n - 1):
        for j in (0, n - 1):
            if state[i, j] == NULL and acc_n[i, j] > 0:
                c = acc_n[i, j]
                z[i, j] = acc_v[i, j] / c + scale * (acc_d[i, j] / c) ** hurst * u[i, j]
                state[i, j] = MDI
                filled += 1
    return filled


@njit(cache=True)
def md(z, state, u, scale, hurst, mode, corner):
    """Midpoint displacement of the NULL cells only (in place), coarsest level first.

    NULL corners get ``corner``; every other NULL cell gets the mean of its parents plus
    ``scale * distance^hurst * u``. Known and MDI cells are never changed. Returns the
    number of cells filled.
    """
    n = z.shape[0]
    pi = np.empty(4, np.int64)
    pj = np.empty(4, np.int64)
    filled = 0
    for i in (0, n - 1):
        for j in (0, n - 1):
            if state[i, j] == NULL:
                z[i, j] = corner
                state[i, j] = MD
                filled += 1
    h = (n - 1) // 2
    while h >= 1:
        for sub in range(2):
            if mode == 1 and sub == 1:
                break
            for i in range(0, n, h):
                for j in range(0, n, h):
                    if state[i, j] != NULL or not _in_substep(i, j, h, mode, sub):
                        continue
                    k, d = _parents(i, j, h, mode, n, pi, pj)
                    v = 0.0
                    for q in range(k):
                        v += z[pi[q], pj[q]]
                    z[i, j] = v / k + scale * d ** hurst * u[i, j]
                    state[i, j] = MD
                    filled += 1
        h //= 2
    return filled
