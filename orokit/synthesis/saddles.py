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
           "saddle_level", "plain_dominance", "SaddleTargets"]


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


#: the saddle OT's plain step runs in a round only while the plain-dominance max-bin error exceeds this times the
#: worse of the dominance and prominence errors (tree-only check, 13 regions, seeds 0-1: with 1 the ranges' log
#: prominence drifted, alaska's W1 against the real tree 0.040 -> 0.086; with 2 0.041)
PLAIN_GATE = 2.0


def _plain_neighbours(px: np.ndarray, py: np.ndarray, a: np.ndarray, b: np.ndarray, k: int) -> np.ndarray:
    """Per peak, the ``k + 1`` ridges whose midpoints lie nearest to it (nearest first; shape (n, k + 1))."""
    from scipy.spatial import cKDTree

    mid = np.column_stack([0.5 * (px[a] + px[b]), 0.5 * (py[a] + py[b])])
    m = min(int(k) + 1, a.size)
    return cKDTree(mid).query(np.column_stack([px, py]), k=m)[1].reshape(px.size, m)


def _plain_floor(sz: np.ndarray, key: np.ndarray, near: np.ndarray) -> np.ndarray:
    """Per peak, the lowest saddle of its nearest ridges (``near``) other than its own key ridge: the ``k``
    nearest others (the last column only counts where the key ridge is among the first ``k``)."""
    own = near == key[:, None]
    use = ~own
    if near.shape[1] > 1:
        use[:, -1] &= own[:, :-1].any(axis=1)  # k others: the (k+1)-th only replaces the key ridge
    s = np.where(use, sz[near], np.inf)
    return s.min(axis=1)


def plain_dominance(pz: np.ndarray, px: np.ndarray, py: np.ndarray, a: np.ndarray, b: np.ndarray, sz: np.ndarray,
                    k: int = 16) -> np.ndarray:
    """Each peak's prominence over its height above the local plain, ``min(1, p / (h - s0))``, ``s0`` the lowest
    saddle of the ``k`` ridges nearest to the peak (by their midpoints) other than its key ridge: a dominance over
    the lowest nearby saddle instead of over sea level (1 when the key saddle is that low or lower; NaN for the
    roots). A dune field's real dunes stand with 90 % of their height (median) above it, the OT's twins 74 %.

    >>> pz = np.array([100.0, 90.0, 80.0]); a = np.array([0, 1]); b = np.array([1, 2])
    >>> plain_dominance(pz, np.array([0.0, 1.0, 2.0]), np.zeros(3), a, b, np.array([50.0, 70.0]), k=1).round(3).tolist()
    [nan, 1.0, 0.333]
    """
    key = key_saddles(pz, a, b, sz)
    out = np.full(pz.size, np.nan)
    has = key >= 0
    if not has.any():
        return out
    s0 = _plain_floor(sz, key, _plain_neighbours(px, py, a, b, k))
    ks = sz[np.maximum(key, 0)]
    with np.errstate(divide="ignore", invalid="ignore"):
        q = np.where(ks <= s0, 1.0, (pz - ks) / (pz - s0))
    out[has] = np.clip(q[has], 0.0, 1.0)
    return out


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
    plain: list | None = None  # per group: FeatureHistogram of plain_dominance, or None (not followed)


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
             floor=None, level=None, level_weight=0.0, plain_near=None):
    """One OT assignment (dominance, prominence or plain); returns new saddle elevations.

    With ``level`` (per ridge, m) the cost also holds ``level_weight * (new saddle - level)^2 / |AB|``.
    ``kind="plain"`` assigns :func:`plain_dominance` targets (``plain_near``: each peak's nearest ridges): the
    target prominence is ``q (h - s0)``, ``s0`` the lowest saddle of its nearby ridges as they are before the
    step; a peak whose current value already lies in the target's histogram bin keeps its saddle, so a tree
    whose histogram already matches barely moves. Peaks with no nearby saddle below them (``s0 >= h``, value 1
    whatever their key saddle) take the highest targets and keep their saddles.

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
        if kind == "plain":
            assert targets.plain is not None and plain_near is not None
            hist = targets.plain[g]
            base_all = pz - _plain_floor(sz, key, plain_near)
            want_all = np.sort(hist.sample(rows_all.size, rng))
            fixed = base_all[rows_all] <= 0  # value 1 whatever happens: they take the highest targets
            want_all = want_all[: want_all.size - int(fixed.sum())]
            rows_all = rows_all[~fixed]
            if rows_all.size == 0:
                continue
            h_all = base_all[rows_all]  # the target prominence is q times this
        else:
            hist = targets.dominance[g] if kind == "dominance" else targets.prominence[g]
            want_all = hist.sample(rows_all.size, rng)
            h_all = pz[rows_all]
        e_all = key[rows_all]

        edges = np.asarray(hist.edges, float)
        last_open = hist.open_last or kind != "prominence"
        scale = h_all if kind != "prominence" else np.ones(rows_all.size)

        def target_prom(rows, w):
            """Target prominence of value(s) ``w``: ``w`` times the row's scale, or (plain) the current
            prominence if its value already lies in w's bin."""
            tp = w * scale[rows]
            if kind != "plain":
                return tp
            j = np.clip(np.searchsorted(edges, w, side="right") - 1, 0, edges.size - 2)
            lo = edges[j] * scale[rows]
            top = (j == edges.size - 2) & last_open
            hi = np.where(top, np.inf, edges[np.minimum(j + 1, edges.size - 1)] * scale[rows])
            p0 = prom[rows_all[rows]]
            return np.where((p0 >= lo) & (p0 < hi), p0, tp)

        def cost_fn(blk, w):
            tp = target_prom(blk[:, None], w[None, :])
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
        new_prom = target_prom(np.arange(rows_all.size), got)
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


def max_bin_errors(pz, a, b, sz, targets: SaddleTargets, plain_values: np.ndarray | None = None) -> tuple[float, ...]:
    """Worst max-bin error of dominance and prominence (and of the plain dominance, ``plain_values`` per peak,
    when ``targets.plain`` is given), pooled over each type's groups."""
    key = key_saddles(pz, a, b, sz)
    prom = np.where(key >= 0, pz - sz[np.maximum(key, 0)], pz)
    owner = targets.owner if targets.owner is not None else list(range(len(targets.dominance)))
    feats = [(targets.dominance, prom / pz), (targets.prominence, prom)]
    if targets.plain is not None:
        assert plain_values is not None
        feats.append((targets.plain, plain_values))
    err = [0.0] * len(feats)
    for t in sorted(set(owner)):
        groups = [g for g in range(len(owner)) if owner[g] == t]
        m_all = np.isin(targets.group, groups) & (key >= 0)
        if not m_all.any():
            continue
        for i, (hists, vals) in enumerate(feats):
            want = np.zeros(hists[groups[0]].n_bins)
            for g in groups:
                want += hists[g].probabilities() * ((targets.group == g) & (key >= 0)).sum()
            got = hists[groups[0]].histogram(vals[m_all]) * m_all.sum()
            err[i] = max(err[i], float(np.abs(got - want).max() / m_all.sum()))
    return tuple(err)


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
    plain_k: int = 16,
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
    plain_k : with ``targets.plain``, a round whose plain-dominance max-bin error (:func:`plain_dominance` over
        the lowest saddle of the ``plain_k`` nearest ridges) exceeds :data:`PLAIN_GATE` times the dominance's
        and the prominence's ends with an assignment of plain-dominance targets (each peak whose value lies in
        its target's bin keeping its saddle), and the rounds are judged on all three features' max-bin errors:
        a type whose twin already matches it keeps the same saddles.

    Returns
    -------
    sz : new saddle elevations (the best round's), info : dict with ``iterations``,
    ``errors`` (per round: dominance, prominence[, plain dominance] max-bin errors).
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

    plain_near = None
    if targets.plain is not None and a.size > 1:
        plain_near = _plain_neighbours(px, py, a, b, plain_k)
    elif targets.plain is not None:
        targets = SaddleTargets(targets.group, targets.dominance, targets.prominence, targets.owner)  # one ridge

    def errors(s: np.ndarray) -> tuple[float, ...]:
        if plain_near is None:
            return max_bin_errors(pz, a, b, s, targets)
        return max_bin_errors(pz, a, b, s, targets, plain_dominance(pz, px, py, a, b, s, k=plain_k))

    best = sz.copy()
    best_err = _judged(errors(sz))
    history = []
    it = 0
    stale = 0
    start = sz
    for it in range(1, max_iterations + 1):
        if it <= restarts:
            sz = start  # the first rounds all start from the initial saddles (restarts)
        kk = keep_keys if it > restarts else 0
        sz = _ot_step("dominance", pz, a, b, sz, hmax, ridge_len, movable, targets, rng, block_size,
                      kk, floor, lvl(sz), level_weight)
        sz = _ot_step("prominence", pz, a, b, sz, hmax, ridge_len, movable, targets, rng, block_size,
                      kk, floor, lvl(sz), level_weight)
        # the plain step only while it is by far the worst matched of the three: a type whose twin already
        # matches it keeps the paper's rounds (and its bytes: no draw is made)
        if plain_near is not None and (lambda e: e[2] / PLAIN_GATE > max(e[:2]))(errors(sz)):
            sz = _ot_step("plain", pz, a, b, sz, hmax, ridge_len, movable, targets, rng, block_size,
                          kk, floor, lvl(sz), level_weight, plain_near)
        errs = errors(sz)
        history.append([round(e, 5) for e in errs])
        logger.debug("saddle OT round %d: max bin errors (dominance, prominence[, plain]) %s", it, history[-1])
        if _judged(errs) < best_err - tol:
            stale = 0
        else:
            stale += 1
        if _judged(errs) < best_err:
            best, best_err = sz.copy(), _judged(errs)
        if it == restarts:
            sz = best  # continue from the best restart
        if stale >= patience and it > restarts:
            break
    return best, {"iterations": it, "errors": history}


def _judged(errs: tuple[float, ...]) -> float:
    """The error a round is judged by: the worst of dominance and prominence, and of the plain dominance's
    over :data:`PLAIN_GATE` when it is followed."""
    return max(*errs[:2], *(e / PLAIN_GATE for e in errs[2:]))


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
