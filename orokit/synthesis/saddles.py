"""Saddle elevations and positions of a synthesized Divide Tree.

Elevations follow the paper's alternating optimal-transport assignment (Argudo et
al. 2019, section 5.4): sampled target dominances (then prominences) are assigned
to peaks by exact optimal transport (POT ``ot.emd``) with cost
``(delta_pi)^2 / |Pa - Pb|`` (infinite when the key saddle would leave
``[0, min(h_a, h_b)]``), and each peak's key saddle is moved to realise its target.
Moving saddles can change which saddle is a peak's key saddle, so the two steps
alternate until the histogram errors stop improving.

Beyond the paper, saddle *positions* are then chosen so that the key-saddle distance
and direction follow the type's histograms (:func:`place_key_saddles`), and every
peak is guaranteed a prominence >= ``eps`` (:func:`enforce_min_prominence`).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from orokit._typing import SeedLike
from orokit.topology import _kernels as _topo

logger = logging.getLogger(__name__)

__all__ = ["forced_prominence", "forced_tail", "key_saddles", "assign_saddle_elevations", "enforce_min_prominence", "place_key_saddles",
           "saddle_level", "SaddleTargets"]


def saddle_level(pz: np.ndarray, px: np.ndarray, py: np.ndarray, a: np.ndarray, b: np.ndarray, sz: np.ndarray,
                 k: int = 16) -> float:
    """How far nearby saddles lie from one level: median over the ridges of ``(m - s0) / (p - s0)``, over the
    ``k`` ridges nearest to the ridge's midpoint, ``m`` and ``s0`` the median and lowest of their saddles, ``p``
    the highest of their end peaks (dimensionless; NaN without ridges). A field of domes on a plain has its saddles
    at one level (sahara's tree 0.08, gobi 0.22, steep ranges 0.37-0.58: dune16's ``L`` on ridge midpoints).

    >>> pz = np.array([100.0, 110.0, 120.0, 130.0]); a = np.array([0, 1, 2]); b = np.array([1, 2, 3])
    >>> saddle_level(pz, np.arange(4.0), np.zeros(4), a, b, np.array([50.0, 60.0, 80.0]), k=3)
    0.125
    """
    if a.size == 0:
        return float("nan")
    from scipy.spatial import cKDTree

    mid = np.column_stack([0.5 * (px[a] + px[b]), 0.5 * (py[a] + py[b])])
    near = cKDTree(mid).query(mid, k=min(int(k), a.size))[1].reshape(a.size, -1)
    s = sz[near]
    s0 = s.min(axis=1)
    top = np.maximum(pz[a], pz[b])[near].max(axis=1)
    return float(np.median((np.median(s, axis=1) - s0) / np.maximum(top - s0, 1e-9)))


def key_saddles(pz: np.ndarray, a: np.ndarray, b: np.ndarray, sz: np.ndarray) -> np.ndarray:
    """Key ridge (edge index, -1 for roots) of every peak (elder rule; ties: lower id higher)."""
    order = np.lexsort((np.arange(a.size), -sz))
    keys = np.arange(pz.size, dtype=np.int64)
    _, key_edge, _, _ = _topo.kruskal_sweep(
        pz, keys, a[order], b[order], sz[order], order.astype(np.int64), np.full(pz.size, -np.inf)
    )
    out = np.full(pz.size, -1, np.int64)
    has = key_edge >= 0
    out[has] = order[key_edge[has]]
    return out


def forced_prominence(pz: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Least prominence each peak can have on ridges ``a``-``b`` (m; NaN for roots).

    Every saddle is raised to its ridge's lower end, the highest it can be; a peak's prominence then
    only comes from how much lower the peaks on its way to higher ground are. A tree whose high peaks
    stand among low neighbours has a heavy tail here whatever its saddles are: no saddle assignment
    gives it the prominences of a real tree whose high peaks sit on massifs.
    """
    top = np.minimum(pz[a], pz[b])
    key = key_saddles(pz, a, b, top)
    return np.where(key >= 0, pz - top[np.maximum(key, 0)], np.nan)


def forced_tail(pz: np.ndarray, a: np.ndarray, b: np.ndarray, threshold_m: float) -> float:
    """Share of the keyed peaks whose :func:`forced_prominence` reaches ``threshold_m`` (NaN: no keyed peak)."""
    f = forced_prominence(pz, a, b)
    f = f[np.isfinite(f)]
    return float((f >= threshold_m).mean()) if f.size else float("nan")


@dataclass
class SaddleTargets:
    """Target histograms per peak group (terrain type index in ``group``)."""

    group: np.ndarray  # int per peak
    dominance: list  # per group: FeatureHistogram
    prominence: list
    owner: list | None = None  # per group: terrain-type index (errors are pooled per type)


def _emd_assign(cost: np.ndarray) -> np.ndarray:
    """Row -> column permutation minimising the total cost (exact OT, uniform weights)."""
    import ot

    n = cost.shape[0]
    if n == 1:
        return np.zeros(1, np.int64)
    w = np.full(n, 1.0 / n)
    plan = ot.emd(w, w, cost, numItermax=max(100000, 50 * n * n))
    return np.argmax(plan, axis=1).astype(np.int64)


def _blocked_targets(want: np.ndarray, cost_fn, block_size: int, rng: np.random.Generator) -> np.ndarray:
    """Assign the values ``want`` to rows by exact OT (``ot.emd``) within blocks.

    Problems larger than ``block_size`` are split into ``k`` random blocks of rows;
    block ``j`` receives every ``k``-th sorted target starting at ``j``, i.e. a
    stratified sub-sample spanning the whole target distribution, so each block is a
    small copy of the full problem. ``cost_fn(rows, targets)`` returns a block's cost
    matrix. Returns the target value of every row (as many rows as targets).
    """
    want = np.sort(want)
    n = want.size
    out = np.empty(n)
    k = max(1, int(np.ceil(n / max(block_size, 2))))
    perm = rng.permutation(n)
    start = 0
    for j in range(k):
        w = want[j::k]
        blk = perm[start: start + w.size]
        start += w.size
        col = _emd_assign(np.ascontiguousarray(cost_fn(blk, w), dtype=np.float64))
        out[blk] = w[col]
    return out


def _ot_step(kind, pz, a, b, sz, hmax, ridge_len, movable, targets: SaddleTargets, rng, block_size, keep_keys=0,
             floor=None, level=None, level_weight=0.0):
    """One OT assignment (dominance or prominence); returns new saddle elevations.

    With ``level`` (per ridge, m) the cost also holds ``level_weight * (new saddle - level)^2 / |AB|``.

    Large problems are split into random row blocks, each receiving a stratified
    sub-sample of the sorted targets and solved exactly with ``ot.emd`` (see
    :func:`_blocked_targets`): O(n * block) memory and time instead of the O(n^2)+
    of one exact plan, with fresh blocks every round.
    """
    key = key_saddles(pz, a, b, sz)
    sz0 = sz
    sz = sz.copy()
    floor = np.zeros_like(hmax) if floor is None else floor
    prom = np.where(key >= 0, pz - sz[np.maximum(key, 0)], pz)
    for g in range(len(targets.dominance)):
        rows_all = np.flatnonzero((targets.group == g) & (key >= 0))
        rows_all = rows_all[movable[key[rows_all]]]
        if rows_all.size == 0:
            continue
        hist = targets.dominance[g] if kind == "dominance" else targets.prominence[g]
        want_all = hist.sample(rows_all.size, rng)
        cur_all = prom[rows_all] / pz[rows_all] if kind == "dominance" else prom[rows_all]
        h_all = pz[rows_all]
        e_all = key[rows_all]

        def cost_fn(blk, w):
            tp = w[None, :] * h_all[blk][:, None] if kind == "dominance" else w[None, :]
            delta = tp - prom[rows_all[blk]][:, None]  # prominence change = lowering of the key saddle
            e = e_all[blk]
            new_h = sz[e][:, None] - delta
            cost = delta**2 / ridge_len[e][:, None]
            if level is not None:
                cost = cost + level_weight * (new_h - level[e][:, None]) ** 2 / ridge_len[e][:, None]
            bad = (new_h < floor[e][:, None]) | (new_h > hmax[e][:, None])
            if bad.all():
                return np.zeros_like(cost)
            big = float(cost[~bad].max(initial=1.0)) * 10.0 + 1.0
            return np.where(bad, big, cost)

        got = _blocked_targets(want_all, cost_fn, block_size, rng)
        new_prom = got * h_all if kind == "dominance" else got
        sz[e_all] = np.clip(sz[e_all] - (new_prom - prom[rows_all]), floor[e_all], hmax[e_all])
    if keep_keys:
        # moves that change which saddle is a peak's key saddle scramble the matched
        # values (the paper's Fig. 11): undo them, a few times as undoing can cascade
        for _ in range(keep_keys):
            new_key = key_saddles(pz, a, b, sz)
            moved = np.flatnonzero((new_key != key) & (key >= 0))
            if moved.size == 0:
                break
            back = np.unique(np.concatenate([key[moved], new_key[moved][new_key[moved] >= 0]]))
            sz[back] = sz0[back]
    return sz


def max_bin_errors(pz, a, b, sz, targets: SaddleTargets) -> tuple[float, float]:
    """Worst max-bin error of dominance and prominence, pooled over each type's groups."""
    key = key_saddles(pz, a, b, sz)
    prom = np.where(key >= 0, pz - sz[np.maximum(key, 0)], pz)
    owner = targets.owner if targets.owner is not None else list(range(len(targets.dominance)))
    err_d = err_p = 0.0
    for t in sorted(set(owner)):
        groups = [g for g in range(len(owner)) if owner[g] == t]
        m_all = np.isin(targets.group, groups) & (key >= 0)
        if not m_all.any():
            continue
        for hists, vals, which in ((targets.dominance, prom / pz, "d"), (targets.prominence, prom, "p")):
            want = np.zeros(hists[groups[0]].n_bins)
            for g in groups:
                want += hists[g].probabilities() * ((targets.group == g) & (key >= 0)).sum()
            got = hists[groups[0]].histogram(vals[m_all]) * m_all.sum()
            e = float(np.abs(got - want).max() / m_all.sum())
            if which == "d":
                err_d = max(err_d, e)
            else:
                err_p = max(err_p, e)
    return err_d, err_p


def assign_saddle_elevations(
    pz: np.ndarray,
    px: np.ndarray,
    py: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    sz: np.ndarray,
    targets: SaddleTargets,
    *,
    movable: np.ndarray | None = None,
    max_iterations: int = 16,
    tol: float = 0.001,
    patience: int = 3,
    keep_keys: int = 3,
    restarts: int = 3,
    block_size: int = 300,
    max_ridge_slope: float | None = None,
    level_weight: float = 0.0,
    level_k: int = 16,
    rng: SeedLike = None,
) -> tuple[np.ndarray, dict]:
    """Alternate dominance and prominence OT assignments until the errors are stable.

    Parameters
    ----------
    pz, px, py : peak elevations and positions.
    a, b : ridge end points; sz : initial saddle elevation per ridge.
    targets : per-group target histograms.
    movable : bool per ridge; fixed saddles (pasted fragments) are never changed.
    max_iterations : upper bound on dominance+prominence rounds.
    tol, patience : stop after ``patience`` rounds in a row that did not improve the
        best worst-feature max-bin error by more than ``tol``.
    block_size : rows per exact OT block (see :func:`_ot_step`).
    restarts : the first ``restarts`` rounds each start from the initial saddles with
        fresh random blocks and targets; the best of them is refined further.
    keep_keys : after the restarts, undo (up to this many times) the saddle
        moves that changed a peak's key saddle (0: the paper's plain alternation).
    max_ridge_slope : None, or a bound (m/m) on each ridge's ``(h_a + h_b - 2 s) / |AB|``
        (both ends' drops to the saddle over the ridge's length): a saddle is never
        lowered below ``(h_a + h_b - max_ridge_slope |AB|) / 2`` (nor below 0), so a
        deep saddle needs a long ridge (the OT treats targets beyond it as infeasible).
    level_weight : > 0 adds ``level_weight * (s - m)^2 / |AB|`` to the OT cost, ``m`` the median of the
        current saddles of the ``level_k`` ridges nearest to the ridge's midpoint (:func:`saddle_level`):
        the targets go to the peaks that stand as far above their neighbours' saddles, so nearby saddles
        lie at one level (a dome field on a plain) without changing the histograms (0: the paper's cost).

    Returns
    -------
    sz : new saddle elevations (the best round's), info : dict with ``iterations``,
    ``errors`` (per round: dominance, prominence max-bin errors).
    """
    rng = np.random.default_rng(rng)
    hmax = np.minimum(pz[a], pz[b])
    ridge_len = np.maximum(np.hypot(px[a] - px[b], py[a] - py[b]), 1e-6)
    movable = np.ones(a.size, bool) if movable is None else np.asarray(movable, bool)
    floor = np.zeros(a.size)
    if max_ridge_slope is not None:
        floor = np.clip(0.5 * (pz[a] + pz[b] - float(max_ridge_slope) * ridge_len), 0.0, hmax)
    near = None
    if level_weight > 0 and a.size > 1:
        from scipy.spatial import cKDTree

        mid = np.column_stack([0.5 * (px[a] + px[b]), 0.5 * (py[a] + py[b])])
        near = cKDTree(mid).query(mid, k=min(int(level_k), a.size))[1].reshape(a.size, -1)

    def lvl(s: np.ndarray) -> np.ndarray | None:
        return None if near is None else np.median(s[near], axis=1)

    best = sz.copy()
    best_err = max(max_bin_errors(pz, a, b, sz, targets))
    history = []
    it = 0
    stale = 0
    start = sz
    for it in range(1, max_iterations + 1):
        if it <= restarts:
            sz = start  # the first rounds all start from the initial saddles (restarts)
        sz = _ot_step("dominance", pz, a, b, sz, hmax, ridge_len, movable, targets, rng, block_size,
                      keep_keys if it > restarts else 0, floor, lvl(sz), level_weight)
        sz = _ot_step("prominence", pz, a, b, sz, hmax, ridge_len, movable, targets, rng, block_size,
                      keep_keys if it > restarts else 0, floor, lvl(sz), level_weight)
        errs = max_bin_errors(pz, a, b, sz, targets)
        history.append([round(errs[0], 5), round(errs[1], 5)])
        logger.debug("saddle OT round %d: max bin error dominance %.4f, prominence %.4f", it, *errs)
        if max(errs) < best_err - tol:
            stale = 0
        else:
            stale += 1
        if max(errs) < best_err:
            best, best_err = sz.copy(), max(errs)
        if it == restarts:
            sz = best  # continue from the best restart
        if stale >= patience and it > restarts:
            break
    return best, {"iterations": it, "errors": history}


def enforce_min_prominence(
    pz: np.ndarray, a: np.ndarray, b: np.ndarray, sz: np.ndarray, eps: float, *, max_rounds: int = 50
) -> tuple[np.ndarray, int]:
    """Lower key saddles until every non-root peak has prominence >= ``eps``.

    Lowering a saddle never decreases any prominence, so the loop only ever helps;
    a key saddle is lowered to ``h - eps`` (never below 0). Returns the new saddle
    elevations and the number of peaks still below ``eps`` (0 unless a peak is lower
    than ``eps`` itself).
    """
    sz = sz.copy()
    for _ in range(max_rounds):
        key = key_saddles(pz, a, b, sz)
        has = key >= 0
        prom = np.where(has, pz - sz[np.maximum(key, 0)], pz)
        low = has & (prom < eps)
        if not low.any():
            return sz, 0
        e = key[low]
        sz[e] = np.maximum(np.minimum(sz[e], pz[low] - eps), 0.0)
    key = key_saddles(pz, a, b, sz)
    has = key >= 0
    prom = np.where(has, pz - sz[np.maximum(key, 0)], pz)
    return sz, int((has & (prom < eps)).sum())


def place_key_saddles(
    px: np.ndarray,
    py: np.ndarray,
    pz: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    sz: np.ndarray,
    group: np.ndarray,
    distance_hists: list,
    direction_hists: list,
    *,
    t_range: tuple[float, float] = (0.03, 0.97),
    max_offset: float = 0.25,
    movable: np.ndarray | None = None,
    block_size: int = 300,
    max_slope_ratio: float | None = None,
    rng: SeedLike = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Saddle positions whose key-saddle distances and directions follow the targets.

    Every ridge's saddle is the key saddle of exactly one peak (elder rule). Its
    position is ``A + t (B - A) + o * perp(B - A)`` with ``t`` in ``t_range`` and the
    perpendicular offset ``o`` within ``max_offset``.

    1. Target distances are sampled (stratified) per peak group and assigned to saddles
       by exact OT (``ot.emd``, in rank blocks of ``block_size``) with cost ``(clip(d, dmin, dmax) - d)^2`` where
       ``[dmin, dmax]`` is the range of distances reachable along the ridge.
    2. ``t`` is solved so the distance is the assigned one (the closest reachable).
    3. Target directions are assigned the same way to saddles, with the cost the
       squared angular gap to the direction reachable by the perpendicular offset;
       the offset then turns the saddle towards its target on the circle of radius
       ``d`` around the peak, as far as ``max_offset`` allows.

    ``max_slope_ratio`` (None: off) narrows ``t_range`` per ridge so that, before the offset,
    neither end falls to the saddle more than that times as steeply as at the even split
    ``t = (h_A - s) / ((h_A - s) + (h_B - s))``, where both halves fall at one slope.
    """
    import ot  # noqa: F401  (fail early with a clear message if POT is missing)

    rng = np.random.default_rng(rng)
    key = key_saddles(pz, a, b, sz)
    owner = np.full(a.size, -1, np.int64)
    has = key >= 0
    owner[key[has]] = np.flatnonzero(has)
    movable = np.ones(a.size, bool) if movable is None else np.asarray(movable, bool)
    ax, ay, bx, by = px[a], py[a], px[b], py[b]
    dx, dy = bx - ax, by - ay
    L = np.maximum(np.hypot(dx, dy), 1e-9)
    sx = ax + 0.5 * dx
    sy = ay + 0.5 * dy
    ok = (owner >= 0) & movable
    qx = np.where(ok, px[np.maximum(owner, 0)], 0.0)
    qy = np.where(ok, py[np.maximum(owner, 0)], 0.0)
    # distance from the owner Q to A + t (B - A) is sqrt(L^2 t^2 - 2 t c + r0^2)
    c = (qx - ax) * dx + (qy - ay) * dy
    r0 = np.hypot(qx - ax, qy - ay)
    t_lo = np.full(a.size, float(t_range[0]))
    t_hi = np.full(a.size, float(t_range[1]))
    if max_slope_ratio is not None:
        # neither half of the ridge falls more than max_slope_ratio x as steeply as the even split
        # (the saddle where both halves have one slope) would
        drop_a = np.maximum(pz[a] - sz, 0.0)
        drop_b = np.maximum(pz[b] - sz, 0.0)
        tot = np.maximum(drop_a + drop_b, 1e-9) * max(float(max_slope_ratio), 1.0)
        t_lo = np.maximum(t_lo, drop_a / tot)
        t_hi = np.minimum(t_hi, 1.0 - drop_b / tot)
        t_lo = np.minimum(t_lo, t_hi)
    t_star = np.clip(c / L**2, t_lo, t_hi)

    def dist_at(t):
        return np.sqrt(np.maximum(L**2 * t**2 - 2 * t * c + r0**2, 0.0))

    dmin = dist_at(t_star)
    dmax = np.maximum(dist_at(t_lo), dist_at(t_hi))
    t_out = np.full(a.size, 0.5)
    off = np.zeros(a.size)
    for g in range(len(distance_hists)):
        rows = np.flatnonzero(ok & (group[np.maximum(owner, 0)] == g))
        if rows.size == 0:
            continue
        lo_r, hi_r = dmin[rows], dmax[rows]

        def dist_cost(blk, w, lo_r=lo_r, hi_r=hi_r):
            return (np.clip(w[None, :], lo_r[blk][:, None], hi_r[blk][:, None]) - w[None, :]) ** 2

        want = _blocked_targets(distance_hists[g].sample(rows.size, rng), dist_cost, block_size, rng)
        d = np.clip(want, lo_r, hi_r)
        # solve L^2 t^2 - 2 c t + r0^2 - d^2 = 0, choosing a root inside t_range
        A2, B2, C2 = L[rows] ** 2, -2 * c[rows], r0[rows] ** 2 - d**2
        disc = np.sqrt(np.maximum(B2**2 - 4 * A2 * C2, 0.0))
        t1 = (-B2 - disc) / (2 * A2)
        t2 = (-B2 + disc) / (2 * A2)
        in1 = (t1 >= t_lo[rows]) & (t1 <= t_hi[rows])
        in2 = (t2 >= t_lo[rows]) & (t2 <= t_hi[rows])
        pick_first = in1 & (~in2 | (rng.random(rows.size) < 0.5))
        t = np.where(pick_first, t1, np.where(in2, t2, t_star[rows]))
        t_out[rows] = np.clip(t, t_lo[rows], t_hi[rows])
    bx0 = ax + t_out * dx
    by0 = ay + t_out * dy
    # direction: rotate around the owner within the allowed perpendicular offset
    for g in range(len(direction_hists)):
        rows = np.flatnonzero(ok & (group[np.maximum(owner, 0)] == g))
        if rows.size == 0:
            continue
        vx, vy = bx0[rows] - qx[rows], by0[rows] - qy[rows]
        r = np.maximum(np.hypot(vx, vy), 1e-9)
        base = np.degrees(np.arctan2(vy, vx)) % 360.0
        span = np.degrees(np.minimum(max_offset * L[rows] / r, np.pi / 2))  # rotation reachable

        def dir_cost(blk, w, base=base, span=span):
            gap = (w[None, :] - base[blk][:, None] + 180.0) % 360.0 - 180.0
            return np.maximum(np.abs(gap) - span[blk][:, None], 0.0) ** 2 + 1e-3 * gap**2

        want = _blocked_targets(direction_hists[g].sample(rows.size, rng), dir_cost, block_size, rng)
        gap = (want - base + 180.0) % 360.0 - 180.0
        ang = np.radians(base + np.clip(gap, -span, span))
        bx0[rows] = qx[rows] + r * np.cos(ang)
        by0[rows] = qy[rows] + r * np.sin(ang)
    sx = np.where(ok, bx0, sx)
    sy = np.where(ok, by0, sy)
    return sx, sy
