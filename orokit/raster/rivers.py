"""River network as the dual of the ridges of a Divide Tree (Argudo et al. 2019, §6.1).

Rivers run along the edges of the Voronoi diagram of the peaks and saddles that do
not cross a ridge; their elevations are bounded by the ridges they are wedged
between and decrease downstream to outlets on the border of the domain.
"""
from __future__ import annotations

import heapq
import logging
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import shapely
from scipy.spatial import Voronoi

from orokit.raster import _kernels
from orokit.raster.spatial import query

logger = logging.getLogger(__name__)

__all__ = ["RidgeSegments", "RiverNetwork", "bounded_beds", "concave_lift", "graded_beds", "local_relief", "ridge_segments",
           "river_network", "saddle_floor"]


@dataclass(frozen=True)
class RidgeSegments:
    """Straight ridge pieces peak -> saddle: endpoints ``(k, 2)`` and elevations ``(k,)``."""

    p0: np.ndarray
    p1: np.ndarray
    z0: np.ndarray
    z1: np.ndarray
    node0: np.ndarray  # index into the node table (peaks then saddles)
    node1: np.ndarray


@dataclass(frozen=True)
class RiverNetwork:
    """An oriented river forest.

    Attributes
    ----------
    xy : (n, 2) node positions.
    elevation : (n,) river bed elevation (metres), non-increasing downstream.
    receiver : (n,) downstream node, -1 at outlets.
    length : (n,) length of the edge to the receiver (0 at outlets).
    order : node ids from the outlets upstream (each receiver comes before its donors).
    outlet : (n,) bool, True for outlet nodes on the border of the domain.
    """

    xy: np.ndarray
    elevation: np.ndarray
    receiver: np.ndarray
    length: np.ndarray
    order: np.ndarray
    outlet: np.ndarray

    @property
    def n_nodes(self) -> int:
        return int(self.xy.shape[0])

    def edges(self) -> np.ndarray:
        """(k, 2) array of ``(donor, receiver)`` pairs."""
        has = self.receiver >= 0
        return np.column_stack([np.flatnonzero(has), self.receiver[has]])

    def drainage_area(self, local_area: np.ndarray) -> np.ndarray:
        """Accumulate per-node ``local_area`` downstream (m^2)."""
        return _kernels.accumulate(self.order, self.receiver, np.asarray(local_area, float))


def ridge_segments(peak_xyz: np.ndarray, saddle_xyz: np.ndarray, edges: np.ndarray) -> RidgeSegments:
    """Split every ridge ``peak_a - saddle - peak_b`` into two straight pieces."""
    n = peak_xyz.shape[0]
    a, b, s = edges[:, 0], edges[:, 1], edges[:, 2]
    peaks = np.concatenate([a, b])
    sad = np.concatenate([s, s])
    return RidgeSegments(
        p0=peak_xyz[peaks, :2], p1=saddle_xyz[sad, :2],
        z0=peak_xyz[peaks, 2], z1=saddle_xyz[sad, 2],
        node0=peaks.astype(np.int64), node1=(n + sad).astype(np.int64),
    )


def local_relief(xy: np.ndarray, peak_xyz: np.ndarray, saddle_xyz: np.ndarray, *,
                 k: int = 16) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The Divide Tree's own relief around ``xy``: the lowest of the ``k`` nearest saddles, the highest
    of the ``k`` nearest peaks and the distance to the farthest of those peaks (three ``(n,)`` arrays;
    ``-inf`` / ``+inf`` / ``+inf`` without saddles or peaks).

    >>> peaks = np.array([[0.0, 0.0, 150.0], [2000.0, 0.0, 120.0]])
    >>> saddles = np.array([[1000.0, 0.0, 100.0]])
    >>> [v.round(1).tolist() for v in local_relief(np.array([[1000.0, 0.0]]), peaks, saddles, k=4)]
    [[100.0], [150.0], [1000.0]]
    """
    xy = np.asarray(xy, float).reshape(-1, 2)
    n = xy.shape[0]
    if saddle_xyz.shape[0] == 0 or peak_xyz.shape[0] == 0 or n == 0:
        return np.full(n, -np.inf), np.full(n, np.inf), np.full(n, np.inf)
    from scipy.spatial import cKDTree

    _, js = query(cKDTree(saddle_xyz[:, :2]), xy, k=min(int(k), saddle_xyz.shape[0]))
    dp, jp = query(cKDTree(peak_xyz[:, :2]), xy, k=min(int(k), peak_xyz.shape[0]))
    s = saddle_xyz[js.reshape(n, -1), 2].min(axis=1)
    p = peak_xyz[jp.reshape(n, -1), 2].max(axis=1)
    return s, p, dp.reshape(n, -1)[:, -1]


def saddle_floor(xy: np.ndarray, peak_xyz: np.ndarray, saddle_xyz: np.ndarray, *, ratio: float,
                 k: int = 16, relief_m: float | None = None, min_ratio: float = 0.0,
                 spread_ratio: float | None = None, level_ratio: float | None = None,
                 relief: Callable[[np.ndarray, int], tuple[np.ndarray, np.ndarray, np.ndarray]] | None = None
                 ) -> np.ndarray:
    """Lowest ground the Divide Tree allows at ``xy``: ``s - ratio * (p - s)``, with ``s`` the lowest of the
    ``k`` nearest saddles and ``p`` the highest of the ``k`` nearest peaks (:func:`local_relief`).

    The tree's own local relief: in a dune field or on a plateau the saddles lie at the level of the
    flats between the hills and the peaks just above them, so the floor is close under the saddles;
    among high peaks over low saddles it lies deep. (7 shared DEMs and their trees, k 16: at ``ratio`` 1 at
    most 1.4 % of a real DEM's cells lie below it (norway), none in gobi, sahara, andes-chile, appalachians;
    at 0.5 up to 6 % (norway), gobi 2.6 %.)

    With ``relief_m`` the ratio follows the local relief ``R = p - s``: ``max(min_ratio, ratio * min(1, R /
    relief_m))`` (never above ``ratio``): low-relief trees (dune fields, plains) keep their beds closer under
    their saddles, high ranges keep the full depth.

    With ``spread_ratio`` the floor lies at most ``spread_ratio`` times the spread of those saddles (their
    median minus their lowest) below the lowest: where the saddles all lie at one level (a field of domes on
    a plain) the ground between the hills stays near that level, whatever the hills' height.

    With ``level_ratio`` ``L0`` the depth shrinks where those saddles lie at one level under taller peaks: times
    ``min(1, (L / L0)^2)``, ``L = spread / R`` the saddles' spread over the local relief (dimensionless; the 13 shared
    DEMs' trees, k 16, median over the domain: sahara's dome field 0.08, gobi and andes-chile 0.22-0.23, the ranges
    0.32-0.59). Domes on a plain keep their low ground near the plain, the saddles' level, whatever their height.

    ``relief(xy, k)``, if given, returns :func:`local_relief` ``(xy, peak_xyz, saddle_xyz, k=k)`` (a caller
    that needs it for the same points elsewhere computes it once).

    >>> peaks = np.array([[0.0, 0.0, 150.0], [2000.0, 0.0, 120.0]])
    >>> saddles = np.array([[1000.0, 0.0, 100.0]])
    >>> saddle_floor(np.array([[1000.0, 500.0]]), peaks, saddles, ratio=0.5, k=4).tolist()
    [75.0]
    >>> saddle_floor(np.array([[1000.0, 500.0]]), peaks, saddles, ratio=1.0, k=4, relief_m=200.0,
    ...              min_ratio=0.1).tolist()
    [87.5]
    >>> saddles = np.array([[1000.0, 0.0, 100.0], [1000.0, 900.0, 104.0], [1000.0, -900.0, 110.0]])
    >>> saddle_floor(np.array([[1000.0, 500.0]]), peaks, saddles, ratio=1.0, k=4, spread_ratio=3.0).tolist()
    [88.0]
    >>> saddle_floor(np.array([[1000.0, 500.0]]), peaks, saddles, ratio=1.0, k=4, level_ratio=0.2).tolist()
    [92.0]
    """
    xy = np.asarray(xy, float).reshape(-1, 2)
    if saddle_xyz.shape[0] == 0 or peak_xyz.shape[0] == 0 or xy.shape[0] == 0:
        return np.full(xy.shape[0], -np.inf)
    if spread_ratio is not None and not float(spread_ratio) >= 0.0:
        raise ValueError(f"spread_ratio must be >= 0, got {spread_ratio!r}")
    if level_ratio is not None and not float(level_ratio) > 0.0:
        raise ValueError(f"level_ratio must be > 0, got {level_ratio!r}")
    if spread_ratio is None and level_ratio is None:
        s, p, _ = local_relief(xy, peak_xyz, saddle_xyz, k=k) if relief is None else relief(xy, k)
    else:  # the same k nearest saddles and peaks as local_relief, with the saddles' median
        from scipy.spatial import cKDTree

        n = xy.shape[0]
        _, js = query(cKDTree(saddle_xyz[:, :2]), xy, k=min(int(k), saddle_xyz.shape[0]))
        _, jp = query(cKDTree(peak_xyz[:, :2]), xy, k=min(int(k), peak_xyz.shape[0]))
        sz = saddle_xyz[js.reshape(n, -1), 2]
        s, p = sz.min(axis=1), peak_xyz[jp.reshape(n, -1), 2].max(axis=1)
        spread = np.median(sz, axis=1) - s
    r = np.maximum(p - s, 0.0)
    if relief_m is None:
        depth = float(ratio) * r
    else:
        if not float(relief_m) > 0.0:
            raise ValueError(f"relief_m must be > 0, got {relief_m!r}")
        rat = np.clip(float(ratio) * np.minimum(r / float(relief_m), 1.0), min(float(min_ratio), float(ratio)),
                      float(ratio))
        depth = rat * r
    if spread_ratio is not None:
        depth = np.minimum(depth, float(spread_ratio) * spread)
    if level_ratio is not None:
        level = np.divide(spread, r, out=np.ones_like(r), where=r > 0) / float(level_ratio)
        depth = depth * np.minimum(level, 1.0) ** 2
    return s - depth


def graded_beds(receiver: np.ndarray, length: np.ndarray, drop: np.ndarray, start: np.ndarray,
                swept: np.ndarray, *, tol: float = 1e-6) -> np.ndarray:
    """Beds that fall evenly along each run of sweep-bound nodes instead of a staircase.

    ``swept`` are the beds after the downstream sweep of ``start`` (each node at most its start value and
    at least ``drop`` below its donor; nodes numbered from the outlets upstream, receivers before donors).
    A node still at its start value (or an outlet) is an anchor; between the anchor that sets a node's bed
    upstream (the head) and the next anchor downstream, the bed falls linearly with the flow distance from
    the head's start value to the lower anchor's bed, so it never lies above the swept bed (the lower
    anchor lies at least the run's drops below the head). Returns the graded beds, before a new sweep.

    >>> g = graded_beds(np.array([-1, 0, 1, 2]), np.array([0.0, 100.0, 100.0, 100.0]),
    ...                 np.array([0.0, 1.0, 1.0, 1.0]), np.array([0.0, 300.0, 300.0, 100.0]),
    ...                 np.array([0.0, 98.0, 99.0, 100.0]))
    >>> g.round(3).tolist()
    [0.0, 33.333, 66.667, 100.0]
    """
    n = swept.size
    anchor = (swept >= start - tol) | (receiver < 0)
    up = np.zeros(n)  # flow distance from the node's head
    head = swept.copy()  # the head's bed
    best = np.full(n, np.inf)  # the lowest candidate from a donor (the one the sweep kept)
    rec, ln, dr, sw = receiver.tolist(), length.tolist(), drop.tolist(), swept.tolist()
    up_l, head_l, best_l, anc = up.tolist(), head.tolist(), best.tolist(), anchor.tolist()
    for v in range(n - 1, -1, -1):  # donors before receivers
        if anc[v]:
            up_l[v], head_l[v] = 0.0, sw[v]
        r = rec[v]
        if r >= 0 and not anc[r]:
            cand = sw[v] - dr[v]
            if cand < best_l[r]:
                best_l[r] = cand
                up_l[r], head_l[r] = up_l[v] + ln[v], head_l[v]
    down_l, low_l = [0.0] * n, list(sw)  # flow distance to the next anchor downstream and its bed
    for v in range(n):  # receivers before donors
        r = rec[v]
        if r >= 0:
            down_l[v] = ln[v] + (0.0 if anc[r] else down_l[r])
            low_l[v] = sw[r] if anc[r] else low_l[r]
    up, head, down, low = (np.asarray(a) for a in (up_l, head_l, down_l, low_l))
    run = up + down
    t = np.divide(up, run, out=np.zeros(n), where=run > 0)
    return np.where(anchor, swept, np.minimum(swept, head + (low - head) * t))


def bounded_beds(receiver: np.ndarray, length: np.ndarray, elevation: np.ndarray, max_slope: np.ndarray
                 ) -> np.ndarray:
    """Beds no steeper than ``max_slope`` (m/m, per node) toward their receiver: from the outlets upstream
    (nodes numbered receivers before donors, as :class:`RiverNetwork`), every bed is lowered to at most its
    receiver's final bed plus ``max_slope x length``. Beds only fall; a profile that fell downstream still
    does (each bed stays at or above its receiver's), and a step where a high tributary meets a deep trunk
    becomes a reach at ``max_slope`` cut back into the tributary.

    >>> bounded_beds(np.array([-1, 0, 1, 1]), np.array([0.0, 100.0, 100.0, 50.0]),
    ...              np.array([0.0, 500.0, 540.0, 510.0]), np.full(4, 0.5)).tolist()
    [0.0, 50.0, 100.0, 75.0]
    """
    slope = np.asarray(max_slope, float)
    if not (slope >= 0.0).all():  # NaN too
        raise ValueError("max_slope must be >= 0 (m/m) at every river node")
    order = np.arange(elevation.size, dtype=np.int64)
    return _kernels.river_rise_bound(order, np.asarray(receiver, np.int64), np.asarray(length, float) * slope,
                                     np.asarray(elevation, float))


def concave_lift(receiver: np.ndarray, length: np.ndarray, area: np.ndarray, top: np.ndarray, bed: np.ndarray, *,
                 concavity: float, area_m2: float = 1.0e6) -> np.ndarray:
    """Concave river profiles (Flint's law ``S = k_s min(1, A_c / A)^theta``) from each outlet to its heads.

    Nodes numbered receivers before donors (as :class:`RiverNetwork`); ``area`` the drainage area (m^2) of each
    node, ``top`` the highest bed each may have (its bound), ``bed`` the current beds (an outlet's is its base).
    Along the flow, ``chi(v) = chi(receiver) + length x min(1, A_c / A(v))^theta`` (0 at the outlets), and a
    profile ``bed(outlet) + k_s chi`` with one steepness ``k_s`` per outlet's basin joins the outlet to its heads
    (nodes without donors): ``k_s`` is the median over the basin's heads of ``(top - bed(outlet)) / chi``, the relief
    the tree gives the basin over its channels' length in chi. Below ``area_m2`` (A_c, the channels' heads) the
    slope stays ``k_s``; downstream it falls as ``A^-theta`` (theta ~0.45 in real ranges). Returns the profile
    (``(n,)``; ``-inf`` where a basin has no head with ``chi > 0``): a lower bound for the beds, which the caller
    caps by ``top`` and sweeps downstream again.

    >>> lift = concave_lift(np.array([-1, 0, 1]), np.array([0.0, 1000.0, 1000.0]), np.array([4e6, 2e6, 1e6]),
    ...                     np.array([0.0, 500.0, 1000.0]), np.zeros(3), concavity=1.0)
    >>> lift.round(1).tolist()
    [0.0, 333.3, 1000.0]
    """
    if not float(concavity) >= 0.0:
        raise ValueError(f"concavity must be >= 0, got {concavity!r}")
    if not float(area_m2) > 0.0:
        raise ValueError(f"area_m2 must be > 0 (m^2), got {area_m2!r}")
    n = receiver.size
    if n == 0:
        return np.zeros(0)
    rec = np.asarray(receiver, np.int64)
    w = np.minimum(1.0, float(area_m2) / np.maximum(np.asarray(area, float), 1e-9)) ** float(concavity)
    step = np.asarray(length, float) * w
    chi, basin = _kernels.chi_and_basin(rec, step)
    head = np.ones(n, bool)
    head[rec[rec >= 0]] = False
    base = np.asarray(bed, float)[basin]
    ok = head & (chi > 0) & np.isfinite(top)
    ks_head = (np.asarray(top, float)[ok] - base[ok]) / chi[ok]
    ks = np.full(n, -np.inf)
    if ok.any():
        b = basin[ok]
        order = np.lexsort((ks_head, b))
        b, kv = b[order], ks_head[order]
        first = np.flatnonzero(np.r_[True, b[1:] != b[:-1]])
        count = np.diff(np.r_[first, b.size])
        med = 0.5 * (kv[first + (count - 1) // 2] + kv[first + count // 2])
        ks[b[first]] = np.maximum(med, 0.0)
    kb = ks[basin]
    return np.where(np.isfinite(kb), base + np.where(np.isfinite(kb), kb, 0.0) * chi, -np.inf)


def _segment_params(p0, p1, q0, q1):
    """Parameter along q of the intersection of segments p and q (rows paired)."""
    r = p1 - p0
    s = q1 - q0
    denom = r[:, 0] * s[:, 1] - r[:, 1] * s[:, 0]
    qp = q0 - p0
    with np.errstate(divide="ignore", invalid="ignore"):
        u = (qp[:, 0] * r[:, 1] - qp[:, 1] * r[:, 0]) / denom
    return np.clip(np.nan_to_num(u, nan=0.5), 0.0, 1.0)


def _flood_from_outlets(start: np.ndarray, src: np.ndarray, dst: np.ndarray, xy: np.ndarray, bnd: np.ndarray,
                        outlet: np.ndarray, base_elevation: float) -> tuple[np.ndarray, np.ndarray, list[int] | np.ndarray]:
    """Priority flood over the river graph (CSR ``start``/``dst``, entries sorted by ``src``) from
    the outlets, lowest bound first: every reached node's receiver, flow distance to its outlet,
    and the nodes in the order they were reached (:func:`_kernels.flood_from_outlets`; the loop
    below where a bound is NaN, whose comparisons in Python's tuples the kernel does not follow)."""
    elen = np.hypot(xy[dst, 0] - xy[src, 0], xy[dst, 1] - xy[src, 1])
    if not np.isnan(bnd).any():
        return _kernels.flood_from_outlets(start.astype(np.int64), dst.astype(np.int64), elen,
                                           np.asarray(bnd, np.float64), np.flatnonzero(outlet).astype(np.int64),
                                           float(base_elevation))
    n = xy.shape[0]
    receiver = np.full(n, -1, np.int64)
    seen = np.zeros(n, bool)
    heap: list[tuple[float, float, int]] = []
    for o in np.flatnonzero(outlet):
        heapq.heappush(heap, (float(min(bnd[o], base_elevation)), 0.0, int(o)))
        seen[o] = True
    # plain lists and the edge lengths computed at once (the same np.hypot values as edge by
    # edge) keep the Python loop fast
    elen_l = elen.tolist()
    start_l, dst_l, bnd_l, seen_l = start.tolist(), dst.tolist(), bnd.tolist(), seen.tolist()
    rec_l, fd_l = receiver.tolist(), [0.0] * n
    order: list[int] = []
    while heap:
        key, dist, v = heapq.heappop(heap)
        order.append(v)
        for k in range(start_l[v], start_l[v + 1]):
            w = dst_l[k]
            if seen_l[w]:
                continue
            seen_l[w] = True
            rec_l[w] = v
            d = elen_l[k]
            fd_l[w] = dist + d
            heapq.heappush(heap, (max(key, bnd_l[w]), dist + d, w))
    return np.asarray(rec_l, dtype=np.int64), np.asarray(fd_l, dtype=np.float64), order


def river_network(
    ridges: RidgeSegments,
    node_xy: np.ndarray,
    extent: tuple[float, float, float, float],
    *,
    base_elevation: float,
    margin_m: float = 5.0,
    slope: float = 0.01,
    cap=None,
    max_sink_m: float | None = None,
    relief_ratio: float = 0.0,
    sink_relief_ratio: float | None = None,
    floor=None,
    graded: bool = False,
    base_slope: float | None = None,
    base_cap=None,
    max_slope=None,
    concavity: float | None = None,
    local_area=None,
    concave_area_m2: float = 1.0e6,
    concave_floor=None,
) -> RiverNetwork:
    """Rivers of a Divide Tree: dual Voronoi edges not crossing a ridge, oriented to outlets.

    Parameters
    ----------
    ridges : straight ridge pieces (see :func:`ridge_segments`).
    node_xy : (k, 2) positions of the peaks and saddles (Voronoi generators).
    extent : ``(xmin, ymin, xmax, ymax)`` of the domain; rivers leave it at outlets.
    base_elevation : elevation of the outlets and lowest allowed river bed (metres).
    margin_m : a river node lies at least this far below every ridge point it faces.
    slope : minimum downstream bed slope (m/m).
    cap : optional callable ``(k, 2) xy -> (k,)`` upper bound of the ground (e.g. the
        flank envelope of the ridges); river beds stay ``margin_m`` below it.
    max_sink_m : a bed lies at most this far below its own bound (``min(ridge crossings, cap) -
        margin_m``) after the downstream sweep (None: no limit). The sweep pulls every bed below
        the lowest bed upstream minus ``slope`` x the distance; over long winding rivers that pins
        them to ``base_elevation`` (gobi: 22 % of the river nodes); with a limit a bed may lie
        above an upstream one (a closed depression, as in endorheic basins).
    floor : optional callable ``(k, 2) xy -> (k,)`` lowest bed (e.g. :func:`saddle_floor`): after the
        sweep every bed, outlets included, is raised to it (above ``cap``: a floor below the nearby saddles
        makes no higher pass), never above the ridges it crosses minus ``margin_m`` (closed depressions may
        form, as with ``max_sink_m``); a bed that crosses no ridge is raised to the floor itself, which
        should lie below the saddles around it.
    graded : after the sweep, the beds between two nodes at their bound fall evenly (:func:`graded_beds`)
        instead of following the cap and then running at ``slope`` (a staircase: steep reaches and flat ones).
    base_slope : after the sweep, a bed lies no lower than ``base_elevation + base_slope x`` its flow distance to
        its outlet (nor above the ridges it faces less ``margin_m``; the cap does not bound it: where the cones reach
        below the base level the beds lay on ``base_elevation`` above them), nor above ``base_cap`` (optional
        callable ``(k, 2) xy -> (k,)``, e.g. the lowest nearby saddle), then the sweep runs again: a long
        river no longer runs flat at ``base_elevation`` (the sweep's floor) for tens of km, a pool at one level
        at the domain's bottom (None: off).
    max_slope : optional callable ``(k, 2) xy -> (k,)`` steepest bed slope (m/m) at each node (e.g. the threshold
        slope of the hillslopes around it): after the sweeps, a pass from the outlets upstream lowers every bed to at
        most its receiver's bed plus ``max_slope x length`` (:func:`bounded_beds`), so a high tributary descends to
        the trunk it joins instead of stepping down to it at the junction (beds only fall: no ridge bound is
        crossed; then ``max_sink_m``, ``sink_relief_ratio`` and ``floor`` as before; None: off).
    concavity : after the sweeps (and ``base_slope``), a bed lies no lower than a concave profile from its outlet
        to the heads of its basin (:func:`concave_lift`: Flint's law ``S ~ A^-concavity`` below ``concave_area_m2``,
        one steepness per basin from its heads' bounds) nor above its own bound (``cap`` and the ridges it faces
        less ``margin_m``; not ``base_cap``), then the sweep runs again (before ``max_slope``): the trunks rise from
        the outlet as real ones do instead of running at ``slope``, and the tributaries meet them higher. Needs
        ``local_area``, a callable ``(k, 2) xy -> (k,)`` area (m^2) draining straight to each node (None: off).
        ``concave_floor`` (optional callable ``(k, 2) xy -> (k,)``, e.g. the ridges' cones at a steeper slope) keeps
        the profile above it: a bed far below its bound makes walls as steep as the drop over their width.

    Returns
    -------
    RiverNetwork

    Notes
    -----
    1. Generators are the peaks and saddles plus a ring of ghost points outside the
       domain, so every Voronoi cell of the tree is bounded.
    2. Voronoi edges crossing a ridge piece are dropped; each crossing bounds the
       elevation of both end vertices by the ridge elevation at the crossing.
    3. Vertices outside the domain are outlets. A priority flood from the outlets,
       lowest bound first, gives every reachable vertex one receiver: a forest.
    4. Bed elevations: ``min(bound - margin, cap - margin, donor - slope * length)`` swept
       from the sources down, never below ``base_elevation``. A vertex whose edges cross
       no ridge has no bound and starts at ``cap - margin`` (the ground the ridges around it
       allow); only without ``cap`` does it start at ``base_elevation + slope * flow
       distance`` (which pinned most river beds near the domain minimum, issue 11).
    """
    xmin, ymin, xmax, ymax = extent
    width, height = xmax - xmin, ymax - ymin
    n_gen = max(node_xy.shape[0], 1)
    spacing = min(float(np.sqrt(width * height / n_gen)), max(width, height) / 8.0)
    pad = max(spacing, 0.02 * max(width, height))
    gx0, gy0, gx1, gy1 = xmin - pad, ymin - pad, xmax + pad, ymax + pad
    nxg = max(int(np.ceil((gx1 - gx0) / spacing)), 4)
    nyg = max(int(np.ceil((gy1 - gy0) / spacing)), 4)
    tx = np.linspace(gx0, gx1, nxg + 1)
    ty = np.linspace(gy0, gy1, nyg + 1)
    ghosts = np.concatenate([
        np.column_stack([tx, np.full_like(tx, gy0)]), np.column_stack([tx, np.full_like(tx, gy1)]),
        np.column_stack([np.full_like(ty[1:-1], gx0), ty[1:-1]]),
        np.column_stack([np.full_like(ty[1:-1], gx1), ty[1:-1]]),
    ])
    gens = np.concatenate([node_xy, ghosts])
    vor = Voronoi(gens, qhull_options="Qbb Qc Qz")
    vv = vor.vertices
    rv = np.asarray(vor.ridge_vertices, dtype=np.int64)
    finite = (rv >= 0).all(axis=1)
    rv = rv[finite]
    inside_box = (vv[:, 0] >= gx0) & (vv[:, 0] <= gx1) & (vv[:, 1] >= gy0) & (vv[:, 1] <= gy1)
    rv = rv[inside_box[rv].all(axis=1)]

    # crossings with ridges
    vlines = shapely.linestrings(np.stack([vv[rv[:, 0]], vv[rv[:, 1]]], axis=1))
    bound = np.full(vv.shape[0], np.inf)
    crossed = np.zeros(rv.shape[0], bool)
    if ridges.p0.shape[0]:
        rlines = shapely.linestrings(np.stack([ridges.p0, ridges.p1], axis=1))
        tree = shapely.STRtree(rlines)
        ei, ri = tree.query(vlines, predicate="intersects")
        if ei.size:
            u = _segment_params(vv[rv[ei, 0]], vv[rv[ei, 1]], ridges.p0[ri], ridges.p1[ri])
            alt = ridges.z0[ri] + u * (ridges.z1[ri] - ridges.z0[ri])
            crossed[ei] = True
            np.minimum.at(bound, rv[ei, 0], alt)
            np.minimum.at(bound, rv[ei, 1], alt)
    keep = rv[~crossed]
    inside = (vv[:, 0] > xmin) & (vv[:, 0] < xmax) & (vv[:, 1] > ymin) & (vv[:, 1] < ymax)
    keep = keep[inside[keep].any(axis=1)]  # edges wholly outside the domain are not rivers

    used = np.unique(keep)
    remap = np.full(vv.shape[0], -1, np.int64)
    remap[used] = np.arange(used.size)
    xy = vv[used]
    bnd = bound[used]
    e = remap[keep]
    outlet = ~inside[used]
    n = used.size
    # adjacency (CSR)
    src = np.concatenate([e[:, 0], e[:, 1]])
    dst = np.concatenate([e[:, 1], e[:, 0]])
    order_e = np.argsort(src, kind="stable")
    src, dst = src[order_e], dst[order_e]
    start = np.searchsorted(src, np.arange(n + 1))

    receiver, flowdist, order = _flood_from_outlets(start, src, dst, xy, bnd, outlet, base_elevation)
    reached = np.asarray(order, dtype=np.int64)
    if reached.size < n:
        logger.debug("%d river nodes cannot reach an outlet; dropped", n - reached.size)
    # compact to the reached nodes
    sel = np.zeros(n, bool)
    sel[reached] = True
    new = np.full(n, -1, np.int64)
    new[reached] = np.arange(reached.size)
    xy = xy[reached]
    bnd = bnd[reached]
    outlet = outlet[reached]
    flowdist = flowdist[reached]
    rec_old = receiver[reached]
    receiver = np.where(rec_old >= 0, new[np.maximum(rec_old, 0)], -1)
    order_arr = np.arange(reached.size, dtype=np.int64)
    length = np.zeros(reached.size)
    has = receiver >= 0
    length[has] = np.hypot(*(xy[has] - xy[receiver[has]]).T)

    h0 = np.where(np.isfinite(bnd), bnd - margin_m, np.inf)
    if cap is not None and xy.shape[0]:
        h0 = np.minimum(h0, np.asarray(cap(xy), float) - margin_m)
    bound_all = h0 + margin_m  # the ground each bed must stay below (inf: none)
    h0 = np.where(np.isfinite(h0), h0, base_elevation + slope * flowdist)
    h0[outlet] = np.minimum(h0[outlet], base_elevation)
    relief = dq = None
    if (relief_ratio > 0 or sink_relief_ratio is not None) and ridges.p0.shape[0] and xy.shape[0]:
        from scipy.spatial import cKDTree

        rxy = np.concatenate([ridges.p0, ridges.p1])
        rzz = np.concatenate([ridges.z0, ridges.z1])
        dq, iq = query(cKDTree(rxy), xy)
        ref = np.where(np.isfinite(bound_all), bound_all, rzz[iq])
        relief = np.maximum(rzz[iq] - ref, 0.0)  # how far the nearest ridge point rises above the bound
    if relief_ratio > 0 and relief is not None and dq is not None:
        g = relief / np.maximum(dq, 1.0)
        node_slope = np.maximum(float(slope), float(relief_ratio) * g)
        # the kernel drops slope x length per edge: a per-node slope is a per-node drop
        drop = length * node_slope
        h = _kernels.river_elevations(order_arr, receiver, drop, h0, 1.0, float(base_elevation))
    else:
        drop = length * float(slope)
        h = _kernels.river_elevations(order_arr, receiver, length, h0, float(slope), float(base_elevation))
    if graded and h.size:
        h = _kernels.river_elevations(order_arr, receiver, drop, graded_beds(receiver, length, drop, h0, h), 1.0,
                                      float(base_elevation))
    if base_slope is not None and h.size:
        if not float(base_slope) >= 0.0:
            raise ValueError(f"base_slope must be >= 0 (m/m), got {base_slope!r}")
        # the cones may reach below the base level (a bed there sits at base_elevation, over its cap): only
        # the ridges the bed faces bound it
        lift = np.minimum(base_elevation + float(base_slope) * flowdist, np.where(np.isfinite(bnd), bnd - margin_m,
                                                                                  np.inf))
        if base_cap is not None:
            lift = np.minimum(lift, np.asarray(base_cap(xy), float) - margin_m)
        h = _kernels.river_elevations(order_arr, receiver, drop, np.maximum(h, lift), 1.0, float(base_elevation))
    else:
        lift = np.full(h.size, -np.inf)
    if concavity is not None and h.size:
        if local_area is None:
            raise ValueError("concavity needs local_area (the area draining straight to each river node)")
        area = _kernels.accumulate(order_arr, receiver, np.asarray(local_area(xy), float))
        profile = concave_lift(receiver, length, area, h0, h, concavity=float(concavity), area_m2=concave_area_m2)
        if concave_floor is not None:
            profile = np.maximum(profile, np.asarray(concave_floor(xy), float))
        # the profile where it lies under the bed's bound, never under the base_slope lift (which alone may stand
        # above a cap that reaches below the base level)
        h = _kernels.river_elevations(order_arr, receiver, drop, np.where(np.isfinite(profile), np.maximum(
            np.minimum(profile, h0), lift), h), 1.0, float(base_elevation))
    if max_slope is not None and h.size:
        h = bounded_beds(receiver, length, h, np.asarray(max_slope(xy), float))
    if max_sink_m is not None:
        h = np.maximum(h, h0 - float(max_sink_m))
    if sink_relief_ratio is not None and relief is not None:
        h = np.maximum(h, np.where(outlet, h, h0 - float(sink_relief_ratio) * relief))
    if floor is not None and xy.shape[0]:
        # the floor lies below the saddles, so above the cap it makes no higher pass; ridge crossings still bound it
        h = np.maximum(h, np.minimum(np.asarray(floor(xy), float), np.where(np.isfinite(bnd), bnd - margin_m, np.inf)))
    logger.info("rivers: %d nodes, %d outlets", h.size, int(outlet.sum()))
    return RiverNetwork(xy=xy, elevation=h, receiver=receiver, length=length, order=order_arr, outlet=outlet)
