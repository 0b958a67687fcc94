"""Poisson-disk samples and their elevations between ridges and rivers (paper §6.2)."""
from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.spatial import cKDTree

from orokit._typing import SeedLike
from orokit.raster import _kernels
from orokit.raster.spatial import query

__all__ = ["apex_distance", "dart_seed", "poisson_darts", "poisson_samples", "valley_width", "sample_elevation", "foot_across_jumps",
           "flank_envelope", "field_elevation"]


def poisson_samples(extent: tuple[float, float, float, float], radius: float, *, rng: SeedLike = None) -> np.ndarray:
    """Blue-noise points of the box ``extent`` at mutual distance ``>= radius``.

    Dart throwing on a background grid (about 30 darts per final point), which gives a
    near-maximal Poisson-disk set; ``scipy.stats.qmc.PoissonDisk`` gives the same
    distribution but takes ~40 s for the 10^5 points of a 90 km domain.
    """
    return poisson_darts(extent, radius, seed=dart_seed(rng))


def dart_seed(rng: SeedLike = None) -> int:
    """The int seed of :func:`poisson_samples`' darts: one draw from ``rng``."""
    return int(np.random.default_rng(rng).integers(0, 2**31 - 1))


def poisson_darts(extent: tuple[float, float, float, float], radius: float, *, seed: int) -> np.ndarray:
    """:func:`poisson_samples` from the darts' int seed (:func:`dart_seed`): draws nothing from a
    Generator, so it can run on any thread while the caller keeps using its own."""
    xmin, ymin, xmax, ymax = extent
    n_expected = (xmax - xmin) * (ymax - ymin) / (radius * radius)
    n_trials = int(max(30 * n_expected, 100))
    return _kernels.poisson_disk(float(xmin), float(ymin), float(xmax), float(ymax), float(radius), n_trials,
                                 int(seed))


def valley_width(drainage_area_m2: np.ndarray, *, coef: float = 0.15, exponent: float = 0.4,
                 bed_slope: np.ndarray | None = None, min_bed_slope: float = 0.01,
                 slope_exponent: float = 0.0, ref_bed_slope: float | None = None) -> np.ndarray:
    """Valley floor width ``w = coef * A^exponent`` in metres (May et al. 2013: w ~ A^0.4).

    With ``bed_slope`` and ``slope_exponent`` > 0 the width also follows the bed slope S,
    ``w * (max(S, min_bed_slope) / ref_bed_slope)^-slope_exponent`` (Finnegan et al. 2005:
    w ~ A^3/8 S^-3/16; wide flat floors only where large drainage meets a gentle bed);
    ``ref_bed_slope`` defaults to ``min_bed_slope`` (never wider than ``coef * A^exponent``).

    >>> valley_width(np.array([1e6]), coef=1.0).round(1).tolist()
    [251.2]
    >>> valley_width(np.array([1e6, 1e6]), coef=1.0, bed_slope=np.array([0.01, 0.16]), slope_exponent=0.5).round(1).tolist()
    [251.2, 62.8]
    """
    w = coef * np.power(np.maximum(drainage_area_m2, 0.0), exponent)
    if bed_slope is not None and slope_exponent > 0:
        ref = float(min_bed_slope if ref_bed_slope is None else ref_bed_slope)
        ratio = np.maximum(np.asarray(bed_slope, float), float(min_bed_slope)) / ref
        w = w * ratio ** -float(slope_exponent)
    return w


def sample_elevation(
    points: np.ndarray,
    ridge_xy: np.ndarray,
    ridge_z: np.ndarray,
    river_xy: np.ndarray,
    river_z: np.ndarray,
    river_w: np.ndarray,
    *,
    ridge_slope: np.ndarray | None = None,
    ridge_floor: np.ndarray | None = None,
    k_neighbours: int = 16,
    floor_slope: float = 0.05,
    floor_relief_ratio: float = 0.0,
    valley_floor_slope: float = 0.0,
    profile: Callable[[np.ndarray], np.ndarray] | None = None,
    tree: cKDTree | None = None,
    border_distance: np.ndarray | None = None,
    beyond_slope: float | None = None,
    river_blend_k: int | None = None,
    river_foot_band: float | None = None,
    river_foot_slope: float = 0.25,
    river_foot_k: int = 32,
    apex_m: float | np.ndarray | None = None,
    crest_round: bool = False,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Elevation of ``points`` from the nearest ridge point q and river point r.

    ``h = h(r)`` when ``d(p, R) < w`` (valley floor), else
    ``h = (1 - a) h(q) + a h(r)`` with ``a = d(p, T) / (d(p, R) + d(p, T) - w)`` (the paper),
    or with ``profile``: ``h = h(r) + (h(q) - h(r)) profile(1 - a)`` (e.g. the learned
    concave :func:`orokit.raster.profiles.hillslope_profile`).
    With ``ridge_slope`` (one value per ridge point), ``h`` is also capped by the cone
    envelope ``max_q h(q) - s_q |p - q|`` over the ``k_neighbours`` nearest ridge points
    (orokit): flanks then fall faster than the ridge rises, so the ground beside a
    saddle stays below it and the saddle stays the highest pass; the floor is
    ``h(r) + g * max(d(p, R) - w, 0)`` (no pit below the drainage), with
    ``g = max(floor_slope, floor_relief_ratio * (h(q) - h(r)) / (d(p, R) + d(p, T) - w))``: a
    share of the local ridge-to-river gradient, so below steep ridges the valley sides stay
    steep instead of a gentle ramp where the cones have fallen.
    ``ridge_floor`` (one value per ridge point) bounds how deep the cones dig
    (:func:`flank_envelope`). ``tree``: a ``cKDTree`` of ``ridge_xy`` already built.
    With ``valley_floor_slope`` > 0 the valley floor is not flat: it rises from the bed at that
    slope (m/m) across the floor, ``h(r) + valley_floor_slope * min(d(p, R), w)``, and the
    hillslope starts from its edge (floors that fall toward the river, not flat pools).
    With ``beyond_slope`` and ``border_distance`` (each point's distance to the domain's border), a point
    beyond its river seen from its ridge point (``(p - r) . (q - r) < 0``) and nearer the border than that
    ridge point lies at ``h(r) - beyond_slope * (d(p, R) - w)``: past the last river toward the border the
    paper's interpolation climbs again (``a`` tends to 1/2) into hills with no tree peak, which the orometry
    enforcement then cuts into flat shelves; the ground now falls away to the border instead.
    With ``river_blend_k`` (>= 2) a hillslope point (``d(p, R) >= w``) takes ``h(r)`` as the inverse-square-distance
    mean of its ``river_blend_k`` nearest river points: the nearest river point's elevation jumps where a high
    tributary's points give way to a deep trunk's (across a hillslope, not on a ridge), which the TIN makes a cliff.
    With ``river_foot_band`` (> 0) the foot is blended only across such a jump (:func:`foot_across_jumps`, the
    ``river_foot_k`` nearest of every 4th river point as the others): points whose bed differs from the nearest
    one's by more than ``river_foot_slope`` x their distance apart (another river, not the same bed upstream)
    join within a band of ``river_foot_band`` x that excess beyond the nearest distance; elsewhere the foot
    stays the nearest bed.
    ``apex_m``: the cones have a rounded apex (:func:`flank_envelope`; one radius, or one per ridge point).
    With ``crest_round`` (and ``apex_m``, ``ridge_slope``) the hillslope's crest is as round as its nearest ridge
    point's cone (curvature ``s / r0``): ``a = f(d(p, T)) / f(L)``, ``L = d(p, R) + d(p, T) - w``, ``f``
    :func:`apex_distance` of the radius r with ``(h(q) - h(r)) / ((L - r / 2) r) = s / r0``
    (``r = L - sqrt(L^2 - 2 (h(q) - h(r)) r0 / s)``; at most L, a parabola from crest to river): the same ends, a
    round crest instead of the line's knife edge, r0 0 the line.
    Returns ``(h, d_ridge, d_river)``.
    """
    tree = tree if tree is not None else cKDTree(ridge_xy)
    near = None
    if ridge_slope is not None:
        # one k-nearest search serves the cones and the nearest ridge point (its first column);
        # where the nearest two are equally far, the single-nearest search decides, as before
        near = _nearest_k(tree, points, k_neighbours)
        dT, iq = near[0][:, 0].copy(), near[1][:, 0].copy()
        if near[0].shape[1] > 1:
            tie = np.flatnonzero(near[0][:, 1] == near[0][:, 0])
            if tie.size:
                dT[tie], iq[tie] = query(tree, points[tie])
    else:
        dT, iq = query(tree, points)  # both cores; same answers
    if river_foot_band is not None and river_xy.shape[0] >= 2:
        dR, ir = query(cKDTree(river_xy), points)
        # the other beds from every 4th river point (lambda apart as the skeleton densifies): k of them reach
        # 4x farther along a river than k of all, so a trunk's many points do not hide the tributary beside it
        cxy, cz = river_xy[::4], river_z[::4]
        dk, jk = query(cKDTree(cxy), points, k=min(int(river_foot_k), cxy.shape[0]))
        dk, jk = dk.reshape(points.shape[0], -1), jk.reshape(points.shape[0], -1)
        hr_blend = foot_across_jumps(dR, river_xy[ir], river_z[ir], dk, cxy[jk], cz[jk],
                                     band=float(river_foot_band), slope=float(river_foot_slope), w0=river_w[ir])
    elif river_blend_k is not None and int(river_blend_k) >= 2 and river_xy.shape[0] >= 2:
        kb = min(int(river_blend_k), river_xy.shape[0])
        dk, jk = query(cKDTree(river_xy), points, k=kb)
        dR, ir = dk[:, 0].copy(), jk[:, 0].copy()
        wk = 1.0 / np.maximum(dk, 1.0) ** 2
        hr_blend = np.sum(wk * river_z[jk], axis=1) / np.sum(wk, axis=1)
    else:
        dR, ir = query(cKDTree(river_xy), points)
        hr_blend = None
    w = river_w[ir]
    hq, hr = ridge_z[iq], river_z[ir]
    if hr_blend is not None:
        hr = np.where(dR < w, hr, hr_blend)
    if valley_floor_slope > 0:
        hr = hr + float(valley_floor_slope) * np.minimum(dR, w)
    denom = np.maximum(dR + dT - w, 1e-9)
    if crest_round and apex_m is not None and ridge_slope is not None:
        # the line's crest gets the cone's curvature s / r0: f's radius r with R / ((L - r / 2) r) = s / r0
        r0 = apex_m if np.ndim(apex_m) == 0 else np.asarray(apex_m, float)[iq]
        rl = denom - np.sqrt(np.maximum(denom * denom - 2.0 * np.maximum(hq - hr, 0.0) * r0
                                        / np.maximum(ridge_slope[iq], 1e-9), 0.0))
        alpha = np.clip(apex_distance(dT, rl) / np.maximum(apex_distance(denom, rl), 1e-9), 0.0, 1.0)
    else:
        alpha = np.clip(dT / denom, 0.0, 1.0)
    if profile is None:
        h = np.where(dR < w, hr, (1.0 - alpha) * hq + alpha * hr)
    else:
        h = np.where(dR < w, hr, hr + (hq - hr) * np.asarray(profile(1.0 - alpha), dtype=np.float64))
    if beyond_slope is not None and border_distance is not None:
        if not float(beyond_slope) >= 0.0:
            raise ValueError(f"beyond_slope must be >= 0 (m/m), got {beyond_slope!r}")
        rxy, qxy = river_xy[ir], ridge_xy[iq]
        away = np.einsum("ij,ij->i", points - rxy, qxy - rxy) < 0.0
        beyond = away & (np.asarray(border_distance, float) < dT) & (dR >= w)
        h = np.where(beyond, hr - float(beyond_slope) * (dR - w), h)
    if ridge_slope is not None:
        assert near is not None
        env = _cone_envelope(*near, ridge_z, ridge_slope, ridge_floor, apex_m)
        # the cones only cap; far from every ridge they would dig pits far below the rivers, so
        # the floor rises gently from the nearest river bed (valley sides, not flat plains)
        g = floor_slope
        if floor_relief_ratio > 0:
            g = np.maximum(floor_slope, floor_relief_ratio * np.maximum(hq - hr, 0.0) / denom)
        floor = np.minimum(hr + g * np.maximum(dR - w, 0.0), h)
        h = np.maximum(np.minimum(h, env), floor)

    return h, dT, dR


def foot_across_jumps(d0: np.ndarray, xy0: np.ndarray, z0: np.ndarray, dk: np.ndarray, xyk: np.ndarray,
                      zk: np.ndarray, *, band: float, slope: float, w0: np.ndarray | float = 0.0) -> np.ndarray:
    """The hillslope's foot from the nearest river point (distance ``d0``, place ``xy0``, bed ``z0``; ``(n,)``) and
    other river points (``dk``, ``xyk``, ``zk``; ``(n, k)``).

    An other point j whose bed differs from ``z0`` by more than ``slope`` x its distance from ``xy0`` (another
    river: along one bed gentler than ``slope`` none qualifies) weighs ``w_j = max(1 - (d_j - d0) / B_j, 0)^2``
    ``x (d0 - w0) / (d_j - w0)`` with ``B_j = band`` x that excess and ``w0`` the nearest river's valley floor
    width (the foot is ``z0`` at the floor's edge, where the hillslope starts); the foot is
    ``(z0 + W z*) / (1 + W)`` with ``W = max w_j`` and ``z*`` the
    ``w``-weighted mean bed of those points. Where the nearest river changes from a high tributary to a deep
    trunk the foot then moves from one bed to the other over a band that widens with the jump (the mean of both
    on the line where they are equally far), instead of stepping there (a cliff band in the TIN); elsewhere it is
    the nearest bed.

    >>> xy = np.array([[0.0, 0.0]]); other = np.array([[[0.0, 1000.0]]])
    >>> foot_across_jumps(np.array([500.0]), xy, np.array([0.0]), np.array([[500.0]]), other, np.array([[600.0]]),
    ...                   band=2.0, slope=0.25).tolist()
    [300.0]
    >>> foot_across_jumps(np.array([100.0]), xy, np.array([0.0]), np.array([[900.0]]), other, np.array([[600.0]]),
    ...                   band=2.0, slope=0.25).tolist()
    [0.0]
    """
    z0c = np.asarray(z0, float)[:, None]
    sep = np.hypot(*np.moveaxis(xyk - np.asarray(xy0, float)[:, None, :], -1, 0))
    width = float(band) * np.maximum(np.abs(zk - z0c) - float(slope) * sep, 0.0)
    d0c, w0c = np.asarray(d0, float)[:, None], np.broadcast_to(np.asarray(w0, float), np.shape(d0))[:, None]
    edge = np.clip((d0c - w0c) / np.maximum(dk - w0c, 1e-9), 0.0, 1.0)
    w = np.where(width > 0.0, np.clip(1.0 - (dk - d0c) / np.maximum(width, 1e-9), 0.0, 1.0) ** 2 * edge, 0.0)
    wsum = np.sum(w, axis=1)
    zs = np.sum(w * zk, axis=1) / np.maximum(wsum, 1e-12)
    wmax = np.max(w, axis=1)
    return (z0c[:, 0] + wmax * zs) / (1.0 + wmax)


def flank_envelope(points: np.ndarray, ridge_xy: np.ndarray, ridge_z: np.ndarray, ridge_slope: np.ndarray,
                   *, ridge_floor: np.ndarray | None = None, k_neighbours: int = 16,
                   tree: cKDTree | None = None, apex_m: float | np.ndarray | None = None) -> np.ndarray:
    """Upper envelope of cones ``h(q) - s_q |p - q|`` over the nearest ridge points q.

    With ``ridge_floor``, the envelope never falls below the lowest ``ridge_floor`` of
    those points: the cones keep the ground beside a saddle below it, but far from the
    ridges they no longer dig canyons far below every saddle around (issue 11:
    plateaus cut by deep valleys, > 60 deg walls).

    With ``apex_m`` (r0 > 0) every cone has a rounded apex: ``h(q) - s_q f(d)``, ``f(d) = d^2 / (2 r0)`` within r0 of
    q and ``d - r0 / 2`` beyond (the same slope there, continuous): a crest whose ground falls at ``s_q`` from the ridge
    line is a knife edge (every render's, session 18: 17-51 m down 100 m beside it, the real DEMs 2-36 m).

    >>> q = np.array([[0.0, 0.0]]); z = np.array([100.0]); s = np.array([1.0])
    >>> flank_envelope(np.array([[30.0, 40.0], [300.0, 400.0]]), q, z, s).tolist()
    [50.0, -400.0]
    >>> flank_envelope(np.array([[30.0, 40.0], [300.0, 400.0]]), q, z, s, ridge_floor=np.array([20.0])).tolist()
    [50.0, 20.0]
    >>> flank_envelope(np.array([[30.0, 40.0], [300.0, 400.0]]), q, z, s, apex_m=100.0).tolist()
    [87.5, -350.0]
    """
    tree = tree if tree is not None else cKDTree(ridge_xy)
    return _cone_envelope(*_nearest_k(tree, points, k_neighbours), ridge_z, ridge_slope, ridge_floor, apex_m)


def apex_distance(d: np.ndarray, r0: float | np.ndarray) -> np.ndarray:
    """The rounded cone's drop per unit slope at distance ``d`` from its apex: ``d^2 / (2 r0)`` within ``r0``,
    ``d - r0 / 2`` beyond (continuous, slope 1 from ``r0`` on); ``r0`` 0 gives the sharp cone ``d``.

    >>> apex_distance(np.array([0.0, 100.0, 300.0, 1000.0]), np.array([200.0, 200.0, 200.0, 0.0])).tolist()
    [0.0, 25.0, 200.0, 1000.0]
    """
    d = np.asarray(d, float)
    r0 = np.broadcast_to(np.asarray(r0, float), d.shape)
    inner = d < r0
    return np.where(inner, d * d / (2.0 * np.where(inner, r0, 1.0)), d - 0.5 * r0)


def _nearest_k(tree: cKDTree, points: np.ndarray, k_neighbours: int) -> tuple[np.ndarray, np.ndarray]:
    """Distances and indices ``(n, k)`` of the ``k_neighbours`` nearest points of ``tree`` (at most all)."""
    k = min(k_neighbours, tree.n)
    dk, ik = query(tree, points, k=k)
    return dk.reshape(points.shape[0], -1), ik.reshape(points.shape[0], -1)


def _cone_envelope(dk: np.ndarray, ik: np.ndarray, ridge_z: np.ndarray, ridge_slope: np.ndarray,
                   ridge_floor: np.ndarray | None, apex_m: float | np.ndarray | None = None) -> np.ndarray:
    """:func:`flank_envelope` of the nearest ridge points ``ik`` at distances ``dk`` (both ``(n, k)``)."""
    if apex_m is not None:
        dk = apex_distance(dk, apex_m if np.ndim(apex_m) == 0 else np.asarray(apex_m, float)[ik])
    env = np.max(ridge_z[ik] - ridge_slope[ik] * dk, axis=1)
    if ridge_floor is not None:
        env = np.maximum(env, np.min(ridge_floor[ik], axis=1))
    return env


def field_elevation(
    shape: tuple[int, int],
    cell_size_m: float,
    ridge_rc: tuple[np.ndarray, np.ndarray],
    ridge_z: np.ndarray,
    river_rc: tuple[np.ndarray, np.ndarray],
    river_z: np.ndarray,
    river_w: np.ndarray,
    *,
    profile: Callable[[np.ndarray], np.ndarray] | None = None,
    beyond_slope: float = 0.05,
    beyond_depth_m: float = np.inf,
    smooth_m: float = 0.0,
) -> np.ndarray:
    """Ground between ridges and rivers on a grid, from exact distance transforms.

    Every cell takes its nearest ridge cell q and nearest river cell r
    (:func:`scipy.ndimage.distance_transform_edt` with indices, Euclidean, all ridge and
    river cells at once): ``h = h(r)`` on the valley floor (``d(p, R) < w(r)``), else
    ``h = h(r) + (h(q) - h(r)) f(u)`` with ``u = a / (a + d(p, T))``, ``a = d(p, R) - w``
    and ``f`` the identity or ``profile``. Unlike a TIN of scattered samples capped by the
    cones of the k nearest ridge points, the surface has no facets and no steps: q and r
    change only on the medial axes of the ridges (the rivers, where ``u = 0``) and of the
    rivers (the ridges, where ``u = 1``).

    ``ridge_rc`` / ``river_rc`` are (rows, cols) of the cells with elevations
    ``ridge_z`` / ``river_z`` (several values per cell: the highest ridge, the lowest
    river); ``river_w`` is the valley floor half-width in metres. Returns float32.

    >>> h = field_elevation((1, 5), 10.0, (np.array([0]), np.array([0])), np.array([100.0]),
    ...                     (np.array([0]), np.array([4])), np.array([0.0]), np.array([0.0]))
    >>> h.round(1).tolist()
    [[100.0, 75.0, 50.0, 25.0, 0.0]]
    """
    from scipy import ndimage

    zt = np.full(shape, -np.inf)
    np.maximum.at(zt, ridge_rc, ridge_z)
    zr = np.full(shape, np.inf)
    np.minimum.at(zr, river_rc, river_z)
    wr = np.zeros(shape)
    np.maximum.at(wr, river_rc, river_w)
    is_ridge = np.isfinite(zt)
    is_river = np.isfinite(zr) & ~is_ridge
    if not is_ridge.any() or not is_river.any():
        raise ValueError("field_elevation needs at least one ridge cell and one river cell")
    dT, (ti, tj) = ndimage.distance_transform_edt(~is_ridge, sampling=cell_size_m, return_indices=True)
    hq = zt[ti, tj]
    dR, (ri, rj) = ndimage.distance_transform_edt(~is_river, sampling=cell_size_m, return_indices=True)
    hr, w = zr[ri, rj], wr[ri, rj]
    # beyond its river, seen from its ridge ((p - r) . (q - r) < 0: between the last river and
    # the border), the ground falls gently instead of rising again into a hill with no peak
    ii, jj = np.indices(shape, sparse=True)
    beyond = (ii - ri) * (ti - ri) + (jj - rj) * (tj - rj) < 0
    del ti, tj, ri, rj, ii, jj
    if smooth_m > 0:
        # h(q) and h(r) are constant on the Voronoi cells of the ridge / river cells and jump
        # across their medial axes (the concave side of a bend): blur them, not the distances
        sigma = smooth_m / cell_size_m
        hq = ndimage.gaussian_filter(hq, sigma, mode="nearest")
        hr = ndimage.gaussian_filter(hr, sigma, mode="nearest")
        w = ndimage.gaussian_filter(w, sigma, mode="nearest")
    a = np.maximum(dR - w, 0.0)
    u = np.where(beyond, 0.0, a / np.maximum(a + dT, 1e-9))
    f = u if profile is None else np.asarray(profile(u), dtype=np.float64)
    h = hr + (hq - hr) * f - np.where(beyond, np.minimum(beyond_slope * a, beyond_depth_m), 0.0)
    h[is_ridge] = zt[is_ridge]
    return h.astype(np.float32)
