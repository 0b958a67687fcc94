"""Brute-force line and prominence parents on a Divide Tree (test oracle).

Written from the definitions only, with breadth-first searches over the tree; it
shares no code with :meth:`orokit.topology.divide_tree.DivideTree.parents`.

- Order: peak i is higher than peak j when its elevation is greater, or equal with a
  lower id. Ridges are ordered from the highest saddle down (saddle elevation, then
  lower saddle id first, then ridge order): a ridge's *position* in that order is its
  height rank (smaller = higher).
- Key ridge of P: among the peaks higher than P, the path from P whose lowest ridge
  (largest position) is highest; that lowest ridge is the key ridge.
- Walk: cross the key ridge; then, while the current peak x is not higher than P, among
  the peaks higher than P still ahead (beyond every ridge crossed so far, reached
  without going below it), take the path from x whose lowest ridge is highest, and
  cross that ridge. The first peak higher than P reached is the line parent.
- Prominence parent: the first peak of P's chain of line parents (lp(P), lp(lp(P)),
  ...) that is more prominent than P: greater prominence, or equal prominence and
  higher; a landmass high point (no key ridge) is more prominent than any other peak.
"""
from __future__ import annotations

from collections import deque

import numpy as np


def _bottlenecks(adj, start, allowed=None):
    """Lowest ridge (largest position, and its index) on the path from start to each node."""
    n = len(adj)
    bott = np.full(n, -2, np.int64)  # -2 = not reached, -1 = start
    via = np.full(n, -1, np.int64)
    bott[start] = -1
    q = deque([start])
    while q:
        x = q.popleft()
        for y, pos, ridge in adj[x]:
            if bott[y] != -2 or (allowed is not None and not allowed[y]):
                continue
            if pos > bott[x]:
                bott[y], via[y] = pos, ridge
            else:
                bott[y], via[y] = bott[x], via[x]
            q.append(y)
    return bott, via


def brute_parents(elevation, saddle_elevation, edges):
    """(line_parent, prominence_parent, prominence, key_ridge) of every peak.

    ``edges`` is a (k, 3) array of (peak_a, peak_b, saddle) rows.
    """
    z = np.asarray(elevation, float)
    sz = np.asarray(saddle_elevation, float)
    edges = np.asarray(edges, np.int64).reshape(-1, 3)
    n = z.size
    order = sorted(range(len(edges)), key=lambda r: (-sz[edges[r, 2]], edges[r, 2], r))
    pos = np.empty(len(edges), np.int64)
    pos[order] = np.arange(len(edges))
    adj = [[] for _ in range(n)]
    for r, (a, b, _) in enumerate(edges):
        adj[a].append((b, pos[r], r))
        adj[b].append((a, pos[r], r))

    def higher(i, j):
        return z[i] > z[j] or (z[i] == z[j] and i < j)

    prom = np.full(n, np.inf)
    key = np.full(n, -1, np.int64)
    lp = np.full(n, -1, np.int64)
    for p in range(n):
        bott, via = _bottlenecks(adj, p)
        cand = [q for q in range(n) if bott[q] >= 0 and higher(q, p)]
        if not cand:
            continue
        best = min(cand, key=lambda q: bott[q])
        k = int(via[best])
        key[p] = k
        prom[p] = z[p] - sz[edges[k, 2]]
        region = (bott >= 0) & (via == k)  # beyond the key ridge, without going lower
        a, b = edges[k, 0], edges[k, 1]
        x = b if region[b] else a
        while not higher(x, p):
            bott, via = _bottlenecks(adj, x, region)
            cand = [q for q in range(n) if bott[q] >= 0 and higher(q, p)]
            best = min(cand, key=lambda q: bott[q])
            r = int(via[best])
            region = (bott >= 0) & (via == r)
            a, b = edges[r, 0], edges[r, 1]
            x = b if region[b] else a
        lp[p] = x
    pp = np.full(n, -1, np.int64)
    for p in range(n):
        x = lp[p]
        while x >= 0 and not (prom[x] > prom[p] or (prom[x] == prom[p] and higher(x, p))):
            x = lp[x]
        pp[p] = x
    return lp, pp, prom, key


def tree_path(edges, n, a, b):
    """Peaks and ridges on the tree path from a to b (inclusive), or None if unconnected."""
    edges = np.asarray(edges, np.int64).reshape(-1, 3)
    adj = [[] for _ in range(n)]
    for r, (u, v, _) in enumerate(edges):
        adj[u].append((v, r))
        adj[v].append((u, r))
    prev = {a: (None, None)}
    q = deque([a])
    while q:
        x = q.popleft()
        for y, r in adj[x]:
            if y not in prev:
                prev[y] = (x, r)
                q.append(y)
    if b not in prev:
        return None
    nodes, ridges = [b], []
    while nodes[-1] != a:
        x, r = prev[nodes[-1]]
        nodes.append(x)
        ridges.append(r)
    return nodes[::-1], ridges[::-1]
