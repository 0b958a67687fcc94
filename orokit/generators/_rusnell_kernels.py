"""Numba kernels of the Rusnell 2009 backend: least-cost fields with profile scaling and blending.

The graph is the 8-connected grid; every undirected edge has a weight ``w_e`` (already
multiplied by the step length, 1 or sqrt 2 cells). Edge ``k`` of cell ``(i, j)`` joins it
to ``(i + DI[k], j + DJ[k])`` for the 4 forward directions (E, SE, S, SW); the backward
ones read the neighbour's forward weight.
"""
from __future__ import annotations

import heapq

import numpy as np
from numba import njit

DI = np.array([0, 1, 1, 1, 0, -1, -1, -1], np.int64)
DJ = np.array([1, 1, 0, -1, -1, -1, 0, 1], np.int64)


@njit(cache=True)
def _edge(w, i, j, k):
    """Weight of the edge from (i, j) in direction k (0..7)."""
    if k < 4:
        return w[i, j, k]
    return w[i + DI[k], j + DJ[k], k - 4]


@njit(cache=True)
def _scale(c, cg, cs, table, use_profile):
    """w_s at a node of cost c whose generator has cost cg (eq. 1 then the slope table)."""
    if not use_profile:
        return 1.0
    if cs <= cg:
        return table[-1]
    cm = (c - cg) / (cs - cg) * cs
    t = cm / cs * (table.size - 1)
    if t <= 0.0:
        return table[0]
    if t >= table.size - 1:
        return table[-1]
    k = int(t)
    f = t - k
    return table[k] * (1.0 - f) + table[k + 1] * f


@njit(cache=True)
def cost_field(w, gen_i, gen_j, gen_c, cs, table, use_profile, ca, halt_frac, stamp, tag, cost, src, touched, fixed,
               stop):
    """Least-cost field from the generators (in place over the cells it reaches).

    Cost of the next node: ``c + w_e * w_s(c)`` (w_s from the profile table at the
    node's ``c_m``, eq. 1). Generators keep their own cost (never relaxed: ``fixed`` is
    set to ``tag`` on them). The search does not expand a node whose cost is within 0.5
    of ``cs`` or, when ``ca`` is given (non-empty), whose height ``cs - c`` is below
    ``halt_frac * (cs - ca)``. Cells reached get ``stamp = tag``; ``cost`` and ``src``
    (the generator's cost) are valid there; their flat indices are ``touched[:m]``.
    Cells where ``stop`` (non-empty) is non-zero are reached but never expanded (water halts
    the search). Returns ``m``.
    """
    ny, nx = stamp.shape
    heap = [(0.0, np.int64(0), 0.0)]
    heap.pop()
    m = 0
    for g in range(gen_i.size):
        i, j = gen_i[g], gen_j[g]
        fixed[i, j] = tag
        if stamp[i, j] != tag:
            stamp[i, j] = tag
            touched[m] = i * nx + j
            m += 1
        elif gen_c[g] >= cost[i, j]:
            continue
        cost[i, j] = gen_c[g]
        src[i, j] = gen_c[g]
        heapq.heappush(heap, (gen_c[g], np.int64(i * nx + j), gen_c[g]))
    use_ca = ca.size > 0
    use_stop = stop.size > 0
    while heap:
        c, idx, cg = heapq.heappop(heap)
        i = idx // nx
        j = idx % nx
        if c > cost[i, j]:
            continue
        if c >= cs - 0.5:
            continue
        if use_ca and (cs - c) < halt_frac * (cs - ca[i, j]):
            continue
        if use_stop and stop[i, j] != 0 and fixed[i, j] != tag:
            continue
        ws = _scale(c, cg, cs, table, use_profile)
        for k in range(8):
            r = i + DI[k]
            q = j + DJ[k]
            if r < 0 or r >= ny or q < 0 or q >= nx or fixed[r, q] == tag:
                continue
            nc = c + _edge(w, i, j, k) * ws
            fresh = stamp[r, q] != tag
            if fresh or nc < cost[r, q]:
                if fresh:
                    stamp[r, q] = tag
                    touched[m] = r * nx + q
                    m += 1
                cost[r, q] = nc
                src[r, q] = cg
                heapq.heappush(heap, (nc, np.int64(r * nx + q), cg))
    return m


@njit(cache=True)
def blend_add(touched, m, cost, cs, b, num, den):
    """Add one feature's field to the blend sums of eq. 2 (the ``m`` cells it reached, below c_s)."""
    nx = cost.shape[1]
    for t in range(m):
        i = touched[t] // nx
        j = touched[t] % nx
        if cost[i, j] < cs:
            h = cs - cost[i, j]
            hb = h ** b
            num[i, j] += hb * h
            den[i, j] += hb
