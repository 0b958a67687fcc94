"""Sparse terrain skeleton of a Divide Tree (Argudo et al. 2019, §6): refined ridges,
dual rivers, Poisson samples with interpolated elevations, constrained TIN."""
from __future__ import annotations

import logging
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from orokit._typing import SeedLike
from orokit.errors import DivideTreeError
from orokit.raster.interpolate import dart_seed, flank_envelope, poisson_darts, sample_elevation, valley_width
from orokit.raster.params import RIDGE_TAIL_SLOPE, RenderParams
from orokit.raster.profiles import hillslope_profile, ridge_profile, threshold_profile
from orokit.raster.refine import Polylines, densify, refine_segments
from orokit.raster.rivers import (RidgeSegments, RiverNetwork, local_relief, ridge_segments, river_network,
                                  saddle_floor)
from orokit.raster.spatial import query
from orokit.raster.tin import TIN, constrained_tin

logger = logging.getLogger(__name__)

__all__ = ["TerrainSkeleton", "build_skeleton", "crest_apex", "lone_pieces", "relief_slope", "separate_saddles", "tree_extent", "tree_gradient"]


@dataclass(frozen=True)
class TerrainSkeleton:
    """Sparse intermediate products: refined ridges and rivers, river forest and TIN."""

    ridges: Polylines
    rivers: Polylines
    river_network: RiverNetwork
    tin: TIN
    extent: tuple[float, float, float, float]
    node_xyz: np.ndarray  # peaks then used saddles (x, y, z)
    n_peaks: int
    timings: dict[str, float] = field(default_factory=dict)
    piece_saddle: np.ndarray | None = None  # saddle (0..m-1) of each straight ridge piece
    edges: np.ndarray | None = None  # (m, 3) peak_a, peak_b, saddle (0..m-1, rows of node_xyz after the peaks)


#: with ``crest_relief_m`` the samples lie at least this x lam from the ridges (0.5 x lam otherwise)
CREST_SAMPLE_RATIO = 0.25


def _tree_arrays(tree) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Peaks (n, 3), used saddles (m, 3) and edges (m, 3) with renumbered saddles."""
    if tree.n_peaks == 0:
        raise DivideTreeError("the Divide Tree has no peaks; nothing to render")
    tree.validate()
    p = tree.peaks[["x", "y", "elevation"]].to_numpy(float)
    s = tree.saddles[["x", "y", "elevation"]].to_numpy(float)
    e = tree.edges[["peak_a", "peak_b", "saddle"]].to_numpy(np.int64).reshape(-1, 3)
    if not np.isfinite(p).all() or (s.size and not np.isfinite(s[np.unique(e[:, 2])]).all()):
        raise DivideTreeError("the Divide Tree has non-finite peak or saddle coordinates/elevations; fix or drop them")
    used = np.unique(e[:, 2])
    remap = np.full(max(s.shape[0], 1), -1, np.int64)
    remap[used] = np.arange(used.size)
    e = e.copy()
    e[:, 2] = remap[e[:, 2]] if e.size else e[:, 2]
    return p, s[used].reshape(-1, 3), e


def tree_extent(tree, *, pad_m: float | None = None) -> tuple[float, float, float, float]:
    """Extent ``(xmin, ymin, xmax, ymax)`` of a tree: ``attrs['extent']``, the synthesis
    ``attrs['domain']`` (x0, y0 = south-west corner, width, height), else the bounding
    box of its peaks and saddles padded by ``pad_m`` (default 5 %, at least 1 km)."""
    attrs = tree.attrs if isinstance(tree.attrs, dict) else {}
    if attrs.get("extent") is not None:
        return tuple(float(v) for v in attrs["extent"])  # type: ignore[return-value]
    dom = attrs.get("domain")
    if isinstance(dom, dict) and {"x0", "y0", "width", "height"} <= set(dom):
        x0, y0 = float(dom["x0"]), float(dom["y0"])
        return (x0, y0, x0 + float(dom["width"]), y0 + float(dom["height"]))
    xy = np.concatenate([tree.peaks[["x", "y"]].to_numpy(float), tree.saddles[["x", "y"]].to_numpy(float)])
    xmin, ymin = xy.min(axis=0)
    xmax, ymax = xy.max(axis=0)
    span = max(xmax - xmin, ymax - ymin)
    pad = pad_m if pad_m is not None else max(1000.0, 0.05 * span)
    return (float(xmin - pad), float(ymin - pad), float(xmax + pad), float(ymax + pad))


def separate_saddles(p: np.ndarray, s: np.ndarray, e: np.ndarray, clearance_m: float) -> np.ndarray:
    """Saddle positions moved along their ridge so each is ``clearance_m`` from both peaks.

    A saddle closer than ``clearance_m`` to one of its two peaks (e.g. in the same raster
    cell, where it would overwrite the peak) slides along the straight peak-peak line,
    keeping its sideways offset, to ``clearance_m`` from the nearer end, or to the middle
    when the ridge is shorter than twice that. Elevations (hence the orometry) are kept.
    """
    s = s.copy()
    if clearance_m <= 0 or not e.size:
        return s
    pa, pb, ps = p[e[:, 0], :2], p[e[:, 1], :2], s[e[:, 2], :2]
    d = pb - pa
    length = np.hypot(d[:, 0], d[:, 1])
    close = (np.hypot(*(ps - pa).T) < clearance_m) | (np.hypot(*(ps - pb).T) < clearance_m)
    close &= length > 0
    if not close.any():
        return s
    u = d[close] / length[close, None]
    rel = ps[close] - pa[close]
    t = rel[:, 0] * u[:, 0] + rel[:, 1] * u[:, 1]
    side = rel - t[:, None] * u
    L = length[close]
    lo = np.minimum(clearance_m, 0.5 * L)
    t = np.clip(t, lo, L - lo)
    # the sideways offset may not bring the saddle back within the clearance
    side *= np.clip(np.minimum(t, L - t) / np.maximum(np.hypot(side[:, 0], side[:, 1]), 1e-9), 0.0, 1.0)[:, None] * 0.5
    s[e[close, 2], :2] = pa[close] + t[:, None] * u + side
    logger.debug("moved %d saddles away from their peaks (clearance %.0f m)", int(close.sum()), clearance_m)
    return s


def tree_gradient(xy: np.ndarray, z: np.ndarray, nodes: np.ndarray, *, k: int = 8,
                  min_distance_m: float = 0.0) -> np.ndarray:
    """Steepest descent from each point ``(xy, z)`` to its ``k`` nearest tree nodes (peaks and
    saddles, ``nodes`` (n, 3)): ``max_j max(z - z_j, 0) / max(|p - p_j|, min_distance_m)``.

    The local relief gradient of the Divide Tree itself: large among high peaks over low saddles,
    small on plateaus and dune fields where the nodes have similar heights.

    >>> nodes = np.array([[0.0, 0.0, 0.0], [1000.0, 0.0, 500.0], [0.0, 2000.0, 0.0]])
    >>> tree_gradient(np.array([[0.0, 1000.0]]), np.array([800.0]), nodes, k=3).tolist()
    [0.8]
    """
    if nodes.shape[0] == 0 or xy.shape[0] == 0:
        return np.zeros(xy.shape[0])
    kk = min(int(k), nodes.shape[0])
    d, j = query(cKDTree(nodes[:, :2]), xy, k=kk)
    d, j = d.reshape(xy.shape[0], -1), j.reshape(xy.shape[0], -1)
    drop = np.maximum(z[:, None] - nodes[j, 2], 0.0)
    return np.max(drop / np.maximum(d, max(float(min_distance_m), 1e-9)), axis=1)


def relief_slope(relief: np.ndarray, slope: float, relief_m: float, *, power: float = 1.0,
                 min_slope: float = 0.0) -> np.ndarray:
    """Cone slope for the tree's local relief: ``slope`` where ``relief >= relief_m``, below it
    ``max(min_slope, slope * (relief / relief_m)^power)`` (never above ``slope``).

    Hillslopes stand near a critical angle only where the relief is large (fast erosion); in low,
    slowly eroding ranges they are gentler (nonlinear diffusion, Roering et al. 1999).

    >>> relief_slope(np.array([0.0, 250.0, 500.0, 2000.0]), 0.5, 500.0, min_slope=0.05).tolist()
    [0.05, 0.25, 0.5, 0.5]
    """
    if relief_m <= 0:
        raise ValueError(f"relief_m must be > 0, got {relief_m!r}")
    r = np.clip(np.asarray(relief, float) / float(relief_m), 0.0, 1.0)
    return np.clip(float(slope) * r ** float(power), min(float(min_slope), float(slope)), float(slope))


def _cone_floor(lines: Polylines, point_origin: np.ndarray, pieces: RidgeSegments, node_z: np.ndarray,
                depth_ratio: float | None, saddle_drop: np.ndarray | None = None) -> np.ndarray | None:
    """Lowest elevation the flank cone of each densified ridge point may reach:
    ``saddle - depth_ratio * (peak - saddle)`` of its ridge piece (peak -> saddle); a
    refined vertex shared by several pieces takes the lowest. None: no floor. With
    ``saddle_drop`` (one value per piece) the depth is at most that: ``min(peak - saddle, drop)``."""
    if depth_ratio is None:
        return None
    hp, hs = node_z[pieces.node0], node_z[pieces.node1]
    depth = hp - hs
    if saddle_drop is not None:
        depth = np.minimum(depth, saddle_drop)
    piece_floor = hs - float(depth_ratio) * depth
    seg_floor = piece_floor[lines.origin] if lines.origin is not None else piece_floor
    vert = np.full(lines.xy.shape[0], np.inf)
    np.minimum.at(vert, lines.segments[:, 0], seg_floor)
    np.minimum.at(vert, lines.segments[:, 1], seg_floor)
    n_dense = point_origin.size - lines.xy.shape[0]
    out = np.empty(point_origin.size)
    out[:n_dense] = piece_floor[point_origin[:n_dense]]
    out[n_dense:] = np.where(np.isfinite(vert), vert, lines.z)
    return out



def plateau_pieces(piece_saddle: np.ndarray, peak_xyz: np.ndarray, saddle_xyz: np.ndarray, max_drop: float,
                   *, k: int = 16, k_far: int = 64) -> np.ndarray:
    """Pieces whose saddle lies where the tree's base level stays flat: at every saddle the drop of the lowest of
    its ``k_far`` nearest saddles below the lowest of its ``k`` nearest, over the local relief (highest of the ``k``
    nearest peaks - lowest of the ``k`` nearest saddles, :func:`local_relief`); its median over the ``k`` saddles
    nearest to the piece's saddle is below ``max_drop`` (a plateau's base level stays level for tens of km, a
    range's falls on to its main valleys)."""
    s16, p16, _ = local_relief(saddle_xyz[:, :2], peak_xyz, saddle_xyz, k=k)
    s64, _, _ = local_relief(saddle_xyz[:, :2], peak_xyz, saddle_xyz, k=k_far)
    ratio = (s16 - s64) / np.maximum(p16 - s16, 1.0)
    _, j = cKDTree(saddle_xyz[:, :2]).query(piece_saddle[:, :2], k=min(int(k), saddle_xyz.shape[0]), workers=-1)
    return np.asarray(np.median(ratio[j.reshape(piece_saddle.shape[0], -1)], axis=1) < float(max_drop))


def spread_pieces(piece_saddle: np.ndarray, peak_xyz: np.ndarray, saddle_xyz: np.ndarray, max_spread: float,
                  *, min_relief_m: float = 0.0, k: int = 16) -> np.ndarray:
    """Pieces whose saddle lies in a field of level saddles under high peaks (volcanoes on a plateau). At every
    saddle the spread of the ``k`` saddles nearest to it, (median - lowest) / local relief (highest of the ``k``
    nearest peaks - that lowest, :func:`local_relief`); a piece is selected where the median of that spread over
    the ``k`` saddles nearest to its saddle is at most ``max_spread`` and its saddle's local relief is at least
    ``min_relief_m`` (a dune field's saddles are level too, under low peaks; a range's spread over its relief)."""
    m = saddle_xyz.shape[0]
    kk = min(int(k), m)
    s_low, p_high, _ = local_relief(saddle_xyz[:, :2], peak_xyz, saddle_xyz, k=k)
    stree = cKDTree(saddle_xyz[:, :2])
    _, js = stree.query(saddle_xyz[:, :2], k=kk, workers=-1)
    med = np.median(saddle_xyz[js.reshape(m, -1), 2], axis=1)
    spread = (med - s_low) / np.maximum(p_high - s_low, 1.0)
    _, j = stree.query(piece_saddle[:, :2], k=kk, workers=-1)
    piece_spread = np.median(spread[j.reshape(piece_saddle.shape[0], -1)], axis=1)
    ps_low, pp_high, _ = local_relief(piece_saddle[:, :2], peak_xyz, saddle_xyz, k=k)
    return np.asarray((piece_spread <= float(max_spread)) & (pp_high - ps_low >= float(min_relief_m)))


def lone_pieces(piece_peak: np.ndarray, peak_xyz: np.ndarray, min_spacing_m: float, *, k: int = 4) -> np.ndarray:
    """Pieces whose peak stands alone: the mean distance from it to the ``k`` nearest other peaks is at least
    ``min_spacing_m`` (a volcano on a plateau, km from the next summit; a range's summits crowd along its crests).

    >>> peaks = np.array([[0.0, 0.0, 9.0], [500.0, 0.0, 8.0], [0.0, 600.0, 8.0], [9000.0, 0.0, 9.0]])
    >>> lone_pieces(peaks[[0, 3]], peaks, 3000.0, k=2).tolist()
    [False, True]
    """
    kk = min(int(k) + 1, peak_xyz.shape[0])
    d, _ = cKDTree(peak_xyz[:, :2]).query(piece_peak[:, :2], k=kk, workers=-1)
    d = d.reshape(piece_peak.shape[0], -1)[:, 1:]  # the piece's own peak first (distance 0)
    return np.asarray(d.mean(axis=1) >= float(min_spacing_m)) if d.shape[1] else np.ones(piece_peak.shape[0], bool)


def steep_ridge_profile(peak: np.ndarray, saddle: np.ndarray, max_slope: float, *, only: np.ndarray | None = None
                        ) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """Weight of the saddle's elevation at ``t`` along each ridge piece (0 at the peak, 1 at the saddle;
    ``peak``, ``saddle`` (m, 3) xyz of each piece's ends) for crests that fall from the peak at ``max_slope``
    and then at :data:`RIDGE_TAIL_SLOPE` to the saddle, never above the straight line: a long, gentle piece
    (a volcano's ridge to a saddle far out on its plateau) drops where the edifice stands and runs low over
    the plain, a short or steep one keeps its straight line. With ``only`` (one bool per piece) the other
    pieces keep their line.

    >>> f = steep_ridge_profile(np.array([[0.0, 0.0, 1000.0]]), np.array([[10000.0, 0.0, 0.0]]), 0.5)
    >>> (1000.0 * (1.0 - f(np.array([0.0, 0.1, 0.5, 1.0]), np.zeros(4, int)))).round(1).tolist()
    [1000.0, 500.0, 100.0, 0.0]
    """
    if not float(max_slope) > 0.0:
        raise ValueError(f"max_slope must be > 0, got {max_slope!r}")
    length = np.hypot(*(saddle[:, :2] - peak[:, :2]).T)
    drop = peak[:, 2] - saddle[:, 2]

    def weight(t: np.ndarray, sid: np.ndarray) -> np.ndarray:
        d, L, h = t * length[sid], length[sid], drop[sid]
        above = np.maximum(h - float(max_slope) * d, np.minimum(RIDGE_TAIL_SLOPE, h / np.maximum(L, 1e-9)) * (L - d))
        above = np.minimum(above, h * (1.0 - t))  # never above the straight line
        w = np.where(h > 0, 1.0 - above / np.where(h > 0, h, 1.0), t)
        return w if only is None else np.where(only[sid], w, t)

    return weight


def tail_points(lines: Polylines, xy: np.ndarray, z: np.ndarray, origin: np.ndarray, piece_saddle: np.ndarray,
                *, only: np.ndarray | None = None, tol_m: float = 0.5) -> np.ndarray:
    """Which densified ridge points ``(xy, z)`` lie on a ridge piece's tail: the part of the crest that runs at
    most :data:`RIDGE_TAIL_SLOPE` above its saddle (``z - saddle <= RIDGE_TAIL_SLOPE x distance + tol_m``;
    :func:`steep_ridge_profile`'s crest past its steep part, or a straight piece that gentle). ``origin``:
    :func:`orokit.raster.refine.densify`'s piece of each point (-1 for the refined vertices, whose piece is read
    from ``lines``' segments); ``piece_saddle`` (m, 3) the saddle of every piece; with ``only`` (one bool per
    piece) the other pieces have no tail.

    A 10 km piece from a 1000-m peak cut at 0.5 m/m: its crest reaches the tail 1.67 km from the peak
    (the refined vertices every 200 m, linear between them).

    >>> from orokit.raster.refine import refine_segments, densify
    >>> ends = np.array([[0.0, 0.0, 1000.0], [10000.0, 0.0, 0.0]])
    >>> lines = refine_segments(ends[:, :2], ends[:, 2], np.array([[0, 1]]), lam=200.0, jitter=0.0,
    ...                         segment_profile=steep_ridge_profile(ends[:1], ends[1:], 0.5))
    >>> xy, z, _, org = densify(lines, 50.0, origin=True)
    >>> tail = tail_points(lines, xy, z, org, ends[1:])
    >>> float(xy[tail, 0].min()), float(xy[~tail, 0].max())
    (1800.0, 1750.0)
    """
    piece = np.asarray(origin, np.int64).copy()
    free = np.flatnonzero(piece < 0)
    if free.size:
        seg_origin = lines.origin if lines.origin is not None else np.arange(lines.segments.shape[0])
        vert = np.full(lines.xy.shape[0], -1, np.int64)
        vert[lines.segments[:, 0]] = seg_origin
        vert[lines.segments[:, 1]] = seg_origin  # a vertex shared by pieces (a tree node) takes one of them
        piece[free] = vert[free - (piece.size - lines.xy.shape[0])]
    ok = piece >= 0
    sxy, sz = piece_saddle[np.maximum(piece, 0), :2], piece_saddle[np.maximum(piece, 0), 2]
    d = np.hypot(*(np.asarray(xy, float) - sxy).T)
    out = ok & (np.asarray(z, float) - sz <= RIDGE_TAIL_SLOPE * d + float(tol_m))
    if only is not None:
        out &= np.asarray(only, bool)[np.maximum(piece, 0)]
    return np.asarray(out)


def crest_apex(xy: np.ndarray, z: np.ndarray, slope: np.ndarray, gradient: np.ndarray, *, length_m: float,
               saddle_xyz: np.ndarray, clearance_m: float) -> np.ndarray:
    """Apex radius r0 of each ridge point's flank cone (``(xy, z)``, cone slope ``slope``) from the tree's local
    relief gradient G there (``gradient``): ``r0 = length_m x s / G``.

    A hillslope is convex at its crest (soil creep: flux ~ slope) and planar at its critical slope below; its hilltop
    curvature grows with the erosion rate (Roering et al. 1999, 2007; Hurst et al. 2012), which grows with the local
    relief: curvature ``G / length_m``, so the crest's slope reaches G ``length_m`` from the crest line and the cone's
    slope s at ``r0`` (the rounded cone ``s d^2 / 2 r0`` within r0, :func:`orokit.raster.interpolate.apex_distance`).
    Steep ranges keep narrow crests, plateaus and low hills get broad round ones. On the 13 shared DEMs the ground 100 m
    beside the tree's pieces lies about 0.6 x 100 m x G below the crest (median by G decile, G = relief of the 16
    nearest peaks and saddles over their distance). Near a saddle the radius shrinks so the saddle stays the highest
    pass: ``r0 <= max(2 (ds - (z - z_s) / s) - clearance_m, 0)`` (``ds``, ``z_s``: the nearest saddle of
    ``saddle_xyz``; the cone of a point ds from the saddle and z - z_s above it then passes below the saddle).

    >>> crest_apex(np.array([[0.0, 0.0], [0.0, 5000.0]]), np.array([600.0, 900.0]), np.array([0.6, 0.25]),
    ...            np.array([0.3, 0.05]), length_m=80.0, saddle_xyz=np.array([[0.0, 50000.0, 0.0]]),
    ...            clearance_m=400.0).round(1).tolist()
    [160.0, 400.0]
    """
    s = np.maximum(np.asarray(slope, float), 1e-9)
    r0 = float(length_m) * s / np.maximum(np.asarray(gradient, float), 1e-6)
    if saddle_xyz.shape[0]:
        ds, js = query(cKDTree(saddle_xyz[:, :2]), xy)
        r0 = np.minimum(r0, np.maximum(2.0 * (ds - np.maximum(z - saddle_xyz[js, 2], 0.0) / s) - float(clearance_m),
                                       0.0))
    return np.asarray(r0)


def _hillslope(params: RenderParams):
    """The ridge-to-river profile of the samples (None: linear)."""
    if params.profiles == "learned":
        return hillslope_profile
    if params.hillslope_convexity > 0:
        c = float(params.hillslope_convexity)
        return lambda u: threshold_profile(u, c)
    return None


def _sample_area(samples: Callable[[], np.ndarray], extent: tuple[float, float, float, float]
                 ) -> Callable[[np.ndarray], np.ndarray]:
    """``xy -> (k,)`` area (m^2) draining straight to each river node ``xy``: each of the ``samples()`` (Poisson
    darts over ``extent``) gives its share of the extent to its nearest node."""
    def local(xy: np.ndarray) -> np.ndarray:
        pts = samples()
        cell_area = (extent[2] - extent[0]) * (extent[3] - extent[1]) / max(pts.shape[0], 1)
        _, near = query(cKDTree(xy), pts)
        return np.bincount(near, minlength=xy.shape[0]) * cell_area

    return local


def build_skeleton(
    tree, *, extent: tuple[float, float, float, float], params: RenderParams = RenderParams(),
    saddle_clearance_m: float = 0.0, rng: SeedLike = None, on_nodes: Callable[[np.ndarray], object] | None = None
) -> TerrainSkeleton:
    """Rivers, refined ridges and rivers, Poisson samples with elevations and the TIN.

    Notes
    -----
    1. Rivers: :func:`orokit.raster.rivers.river_network` on the peaks and saddles.
    2. Ridges and rivers are refined to pieces shorter than ``lam`` with jitter.
    3. Poisson-disk samples at radius ``lam`` over the extent (padded by ``lam``), minus
       those closer than ``lam / 2`` to a ridge or river; each gets its elevation from
       the nearest ridge and river points with valley width ``w ~ A^0.4``.
    4. Constrained Delaunay TIN of all points keeping ridge and river pieces.

    Saddles closer than ``saddle_clearance_m`` to one of their peaks are first moved
    along their ridge (:func:`separate_saddles`; ``render_elevation`` uses 1.5 cells).
    ``on_nodes`` is called with the nodes (:attr:`TerrainSkeleton.node_xyz`) before the TIN is built
    (``render_elevation`` starts its distance transform there).
    """
    rng = np.random.default_rng(rng)
    t = {}
    t0 = time.perf_counter()
    p, s, e = _tree_arrays(tree)
    s = separate_saddles(p, s, e, saddle_clearance_m)
    n = p.shape[0]
    nodes = np.concatenate([p, s])
    lam = float(params.lam)
    ridges = ridge_segments(p, s, e)
    zmin = float(nodes[:, 2].min())
    eps = float(params.min_prominence_m)
    base = zmin - max(eps, params.river_margin)
    if zmin >= 0 > base:
        base = 0.5 * zmin
    learned = params.profiles == "learned"
    seg_profile = None
    only = None
    if params.ridge_max_slope is not None:
        if n < nodes.shape[0]:
            cuts = []
            if params.ridge_plateau_drop is not None:
                cuts.append(plateau_pieces(nodes[ridges.node1], p, s, params.ridge_plateau_drop))
            if params.ridge_plateau_spread is not None:
                cuts.append(spread_pieces(nodes[ridges.node1], p, s, params.ridge_plateau_spread,
                                           min_relief_m=params.ridge_plateau_relief_m))
            if cuts:
                only = np.logical_and.reduce(cuts)
        seg_profile = steep_ridge_profile(nodes[ridges.node0], nodes[ridges.node1], params.ridge_max_slope,
                                          only=only)
    ridge_lines = refine_segments(nodes[:, :2], nodes[:, 2], np.column_stack([ridges.node0, ridges.node1]),
                                  lam=lam, jitter=params.jitter, rng=rng,
                                  profile=(lambda t: 1.0 - ridge_profile(t)) if learned else None,
                                  segment_profile=seg_profile)
    t["refine"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    xmin, ymin, xmax, ymax = extent
    pext = (xmin - lam, ymin - lam, xmax + lam, ymax + lam)
    # the Poisson darts (a numba kernel that releases the GIL) are thrown on a second thread while
    # the rivers are built: their seed is drawn here, before the rivers (which draw nothing from rng),
    # so it is the same draw as when the darts came after the rivers (the same samples), and only this
    # thread ever draws from rng
    pool = ThreadPoolExecutor(1, thread_name_prefix="orokit-darts")
    darts = pool.submit(poisson_darts, pext, lam, seed=dart_seed(rng))
    pool.shutdown(wait=False)
    # rivers run on the medial axis between the refined ridges (Voronoi of all ridge points)
    fine = ridge_lines.segments
    fine_ridges = RidgeSegments(ridge_lines.xy[fine[:, 0]], ridge_lines.xy[fine[:, 1]],
                                ridge_lines.z[fine[:, 0]], ridge_lines.z[fine[:, 1]], fine[:, 0], fine[:, 1])
    rxy, rz, rs, rorig = densify(ridge_lines, lam / 4.0, value="slope", origin=True)
    relief_scale = params.flank_slope_relief_m if params.flank_slope_gradient is None else params.flank_slope_gradient
    if relief_scale is not None and n < nodes.shape[0]:
        s_low, p_high, radius = local_relief(rxy, p, s, k=params.flank_slope_relief_k)
        relief = p_high - s_low
        if params.flank_slope_gradient is not None:
            relief = relief / np.maximum(radius, lam)  # the tree's relief gradient
        base_slope = relief_slope(relief, params.flank_slope, relief_scale,
                                  power=params.flank_slope_relief_power, min_slope=params.flank_slope_min)
        rs = np.maximum(base_slope, params.flank_ratio * rs)
    else:
        rs = np.maximum(params.flank_slope, params.flank_ratio * rs)
    if params.flank_relief_ratio > 0:
        rs = np.maximum(rs, params.flank_relief_ratio * tree_gradient(rxy, rz, nodes, k=params.flank_relief_k,
                                                                      min_distance_m=lam))
    if params.flank_max_slope is not None and n < nodes.shape[0]:
        # steep cones dig valley walls that follow them (> 60 deg tails); beside a saddle
        # (within 2 lambda) they stay steep so the saddle stays the highest pass
        near, _ = query(cKDTree(nodes[n:, :2]), rxy)
        rs = np.where(near > 2.0 * lam, np.minimum(rs, params.flank_max_slope), rs)
    if params.ridge_tail_flank_slope is not None and params.ridge_max_slope is not None and n < nodes.shape[0]:
        tail_only = only
        if params.ridge_tail_spacing_m is not None:
            lone = lone_pieces(nodes[ridges.node0], p, params.ridge_tail_spacing_m)
            tail_only = lone if only is None else only & lone
        tail = tail_points(ridge_lines, rxy, rz, rorig, nodes[ridges.node1], only=tail_only)
        near, _ = query(cKDTree(nodes[n:, :2]), rxy)
        tail &= near > 2.0 * lam  # beside a saddle the cones stay steep: the saddle stays the highest pass
        rs = np.where(tail, np.minimum(rs, params.ridge_tail_flank_slope), rs)
    drop = None
    if params.flank_depth_saddle_ratio is not None and n < nodes.shape[0]:
        # how far each piece's saddle stands above the lowest of the saddles around it
        ps = nodes[ridges.node1]
        s_low, _, _ = local_relief(ps[:, :2], p, s, k=params.flank_depth_saddle_k)
        drop = params.flank_depth_saddle_ratio * np.maximum(ps[:, 2] - s_low, 0.0)
    rfloor = _cone_floor(ridge_lines, rorig, ridges, nodes[:, 2], params.flank_depth, drop)
    rtree = cKDTree(rxy)

    def envelope(xy: np.ndarray) -> np.ndarray:
        return flank_envelope(xy, rxy, rz, rs, ridge_floor=rfloor, tree=rtree, k_neighbours=params.flank_neighbours,
                              apex_m=params.flank_apex_m)

    # the rivers' base cap and floor ask for the tree's relief at the same river nodes (k 16 both by default):
    # one search (the last points asked for are kept)
    relief_memo: list[tuple[np.ndarray, int, tuple[np.ndarray, np.ndarray, np.ndarray]]] = []

    def relief_at(xy: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        xy = np.asarray(xy, float).reshape(-1, 2)
        for mxy, mk, got in relief_memo:
            if mk == k and np.array_equal(mxy, xy):
                return got
        got = local_relief(xy, p, s, k=k)
        relief_memo[:] = [(xy, k, got)]
        return got

    floor_ratio = params.saddle_floor_ratio
    bed_ratio = params.river_bed_slope_ratio
    floor = None if floor_ratio is None else (
        lambda xy: saddle_floor(xy, p, s, ratio=float(floor_ratio), k=params.saddle_floor_k,
                                relief_m=params.saddle_floor_relief_m, min_ratio=params.saddle_floor_min_ratio,
                                spread_ratio=params.saddle_floor_spread, level_ratio=params.saddle_floor_level,
                                relief=relief_at))
    rivers = river_network(fine_ridges, ridge_lines.xy, extent, base_elevation=base,
                           margin_m=params.river_margin, slope=params.river_slope, cap=envelope,
                           max_sink_m=params.river_max_sink_m, relief_ratio=params.river_relief_ratio,
                           sink_relief_ratio=params.river_sink_relief_ratio,
                           floor=floor, graded=params.river_graded, base_slope=params.river_base_slope,
                           base_cap=None if params.river_base_saddle_k is None else
                           (lambda xy: relief_at(xy, int(params.river_base_saddle_k))[0]),
                           max_slope=None if bed_ratio is None else
                           (lambda xy: float(bed_ratio) * rs[query(rtree, xy)[1]]),
                           concavity=params.river_concavity, local_area=_sample_area(darts.result, pext),
                           concave_area_m2=params.river_concave_area_m2,
                           concave_floor=None if params.river_concave_wall_slope is None else
                           (lambda xy: flank_envelope(xy, rxy, rz, np.maximum(rs, float(params.river_concave_wall_slope)),
                                                      tree=rtree, k_neighbours=params.flank_neighbours)))
    t["rivers"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    samples = darts.result()
    # boundary ring so the TIN covers the padded extent
    bx = np.linspace(pext[0], pext[2], max(int(np.ceil((pext[2] - pext[0]) / lam)), 1) + 1)
    by = np.linspace(pext[1], pext[3], max(int(np.ceil((pext[3] - pext[1]) / lam)), 1) + 1)
    ring = np.concatenate([
        np.column_stack([bx, np.full_like(bx, pext[1])]), np.column_stack([bx, np.full_like(bx, pext[3])]),
        np.column_stack([np.full_like(by[1:-1], pext[0]), by[1:-1]]),
        np.column_stack([np.full_like(by[1:-1], pext[2]), by[1:-1]]),
    ])
    # drainage area: each sample's area goes to its nearest river node
    area = rivers.drainage_area(_sample_area(lambda: samples, pext)(rivers.xy))
    river_seg = rivers.edges()
    river_lines = refine_segments(rivers.xy, rivers.elevation, river_seg, lam=lam, jitter=params.jitter,
                                  node_a=area, rng=rng)
    t["refine"] += time.perf_counter() - t0

    t0 = time.perf_counter()
    dense = lam / 4.0
    vxy, vz, va = densify(river_lines, dense) if river_seg.size else (rivers.xy, rivers.elevation, area)
    vslope = None
    if params.valley_slope_exponent > 0 and river_seg.size:
        vslope = densify(river_lines, dense, value="slope")[2]
    vw = valley_width(va, coef=params.valley_coef, bed_slope=vslope, min_bed_slope=params.river_slope,
                      slope_exponent=params.valley_slope_exponent, ref_bed_slope=params.valley_slope_ref)
    apex: float | np.ndarray | None = params.flank_apex_m
    if params.crest_relief_m is not None and n < nodes.shape[0]:
        s_low, p_high, radius = local_relief(rxy, p, s, k=params.flank_slope_relief_k)
        apex = crest_apex(rxy, rz, rs, (p_high - s_low) / np.maximum(radius, lam), length_m=params.crest_relief_m,
                          saddle_xyz=nodes[n:], clearance_m=2.0 * lam)
    pts = np.concatenate([samples, ring])
    border = None
    if params.border_beyond_slope is not None:
        border = np.minimum(np.minimum(pts[:, 0] - xmin, xmax - pts[:, 0]),
                            np.minimum(pts[:, 1] - ymin, ymax - pts[:, 1]))
    h, dT, dR = sample_elevation(pts, rxy, rz, vxy, vz, vw, ridge_slope=rs,
                                 ridge_floor=rfloor, profile=_hillslope(params),
                                 k_neighbours=params.flank_neighbours,
                                 floor_relief_ratio=params.floor_relief_ratio, floor_slope=params.floor_slope,
                                 valley_floor_slope=params.valley_floor_slope, tree=rtree,
                                 border_distance=border, beyond_slope=params.border_beyond_slope,
                                 river_blend_k=params.river_blend_k, river_foot_band=params.river_foot_band,
                                 river_foot_slope=params.river_foot_slope, river_foot_k=params.river_foot_k,
                                 apex_m=apex, crest_round=params.crest_relief_m is not None)
    if floor is not None:
        h = np.maximum(h, floor(pts))  # no ground below the tree's own floor (below every nearby saddle)
    # with round crests the samples come nearer the ridges (the TIN's first facet beside a crest spans to them)
    far = (np.minimum(dT / (CREST_SAMPLE_RATIO if params.crest_relief_m is not None else 0.5), dR / 0.5) >= lam)
    far[samples.shape[0]:] = True  # keep the ring
    pts, h = pts[far], h[far]
    t["samples"] = time.perf_counter() - t0

    if on_nodes is not None:
        on_nodes(nodes)
    t0 = time.perf_counter()
    nr = ridge_lines.xy.shape[0]
    nv = river_lines.xy.shape[0]
    xy = np.concatenate([ridge_lines.xy, river_lines.xy, pts])
    z = np.concatenate([ridge_lines.z, river_lines.z, h])
    segs = np.concatenate([ridge_lines.segments, river_lines.segments + nr]) if nv else ridge_lines.segments
    tin = constrained_tin(xy, z, segs)
    t["tin"] = time.perf_counter() - t0
    logger.info("skeleton: %d ridge pts, %d river pts, %d samples, %d triangles",
                nr, nv, pts.shape[0], tin.n_triangles)
    return TerrainSkeleton(ridge_lines, river_lines, rivers, tin, extent, nodes, n, t, ridges.node1 - n, e)
