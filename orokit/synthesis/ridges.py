"""Ridges of a synthesized Divide Tree: Delaunay triangulation + minimum spanning tree.

Real Divide Trees are close to sub-graphs of the Delaunay triangulation of their
peaks (the paper measured > 95 % of ridges), so ridges are the minimum spanning tree
of the triangulation with weight ``|Pi - Pj| / min(h_i, h_j) ** rho`` (Argudo et al.
2019, eq. 1).
"""
from __future__ import annotations

import logging

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components, minimum_spanning_tree
from scipy.spatial import Delaunay, QhullError

from orokit._typing import SeedLike

logger = logging.getLogger(__name__)

__all__ = ["delaunay_edges", "delaunay_mst", "place_saddles_on_ridges"]


def delaunay_edges(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unique edges (i < j) of the Delaunay triangulation of the points.

    Degenerate inputs (fewer than 3 points, all collinear) fall back to the chain of
    points sorted along their main axis, which is what the triangulation degenerates to.
    """
    n = x.size
    if n < 2:
        return np.empty(0, np.int64), np.empty(0, np.int64)
    pts = np.column_stack([x, y])
    try:
        if n < 3:
            raise QhullError("too few points")
        tri = Delaunay(pts)
        s = tri.simplices
        e = np.concatenate([s[:, [0, 1]], s[:, [1, 2]], s[:, [2, 0]]])
    except (QhullError, ValueError):
        c = pts - pts.mean(axis=0)
        axis = np.linalg.svd(c, full_matrices=False)[2][0] if n > 1 else np.array([1.0, 0.0])
        order = np.argsort(c @ axis, kind="stable")
        e = np.column_stack([order[:-1], order[1:]])
    e = np.sort(e, axis=1)
    e = np.unique(e, axis=0)
    return e[:, 0].astype(np.int64), e[:, 1].astype(np.int64)


def delaunay_mst(
    x: np.ndarray,
    y: np.ndarray,
    z: np.ndarray,
    *,
    rho: float | np.ndarray = 1.0,
    forced: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Minimum spanning tree of the Delaunay graph with the paper's ridge weight.

    Parameters
    ----------
    x, y, z : peak positions (metres) and elevations (values <= 1 m count as 1 m).
    rho : exponent of ``min(h_i, h_j)`` in the weight.
    forced : optional (a, b) ridges that must be in the tree (a pasted fragment);
        they get a weight below every other edge, so the MST contains them.

    Returns
    -------
    a, b : int arrays of the n - 1 ridge end points.
    """
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    z = np.maximum(np.asarray(z, float), 1.0)
    n = x.size
    i, j = delaunay_edges(x, y)
    if np.ndim(rho) == 0:
        r = float(rho)
    else:  # per-peak exponent (mixed terrain types): the lower peak's type decides
        rho = np.asarray(rho, float)
        r = np.where(z[i] <= z[j], rho[i], rho[j])
    w = np.hypot(x[i] - x[j], y[i] - y[j]) / np.minimum(z[i], z[j]) ** r
    # strictly positive weights: csgraph treats explicit zeros as missing edges
    w = np.maximum(w, 1e-12 * max(float(w.max(initial=1.0)), 1.0)) + 1.0
    if forced is not None and len(forced[0]):
        fa, fb = (np.asarray(v, np.int64) for v in forced)
        i = np.concatenate([i, np.minimum(fa, fb)])
        j = np.concatenate([j, np.maximum(fa, fb)])
        w = np.concatenate([w, np.full(fa.size, 1e-9)])
    g = _min_duplicates(i, j, w, n)  # a forced edge that is also a Delaunay edge keeps its small weight
    mst = minimum_spanning_tree(g).tocoo()
    a, b = mst.row.astype(np.int64), mst.col.astype(np.int64)
    if a.size != max(n - 1, 0):  # pragma: no cover - Delaunay graphs are connected
        k, _ = connected_components(g, directed=False)
        logger.warning("ridge graph has %d components", k)
    return a, b


def _min_duplicates(i: np.ndarray, j: np.ndarray, w: np.ndarray, n: int):
    if i.size == 0:
        return coo_matrix((n, n)).tocsr()
    key = i * n + j
    order = np.lexsort((w, key))
    key, i, j, w = key[order], i[order], j[order], w[order]
    first = np.concatenate([[True], key[1:] != key[:-1]])
    return coo_matrix((w[first], (i[first], j[first])), shape=(n, n)).tocsr()


def place_saddles_on_ridges(
    x: np.ndarray,
    y: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    *,
    split: tuple[float, float] = (0.3, 0.7),
    jitter: float = 0.05,
    rng: SeedLike = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Initial saddle positions on ridges: a random split point plus a small planar jitter.

    Returns ``sx, sy, t`` with ``t`` the split fraction from ``a`` to ``b``; the jitter
    is perpendicular to the ridge, uniform within ``jitter`` times its length.
    """
    rng = np.random.default_rng(rng)
    t = rng.uniform(split[0], split[1], a.size)
    off = rng.uniform(-jitter, jitter, a.size)
    dx, dy = x[b] - x[a], y[b] - y[a]
    sx = x[a] + t * dx - off * dy
    sy = y[a] + t * dy + off * dx
    return sx, sy, t
