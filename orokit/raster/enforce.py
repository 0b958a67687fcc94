"""Orometry enforcement: make a rendered raster's Divide Tree the tree it was rendered from."""
from __future__ import annotations

import logging
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from orokit.raster import _kernels
from orokit.raster.rasterize import Grid, set_cells
from orokit.raster.skeleton import TerrainSkeleton
from orokit.topology._kernels import ascent_labels

logger = logging.getLogger(__name__)

__all__ = ["cap_basins", "enforce_orometry"]


def _saddle_normals(skel: TerrainSkeleton) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals of the ridge at every saddle (from its two refined neighbours)."""
    n = skel.n_peaks
    m = skel.node_xyz.shape[0] - n
    seg = skel.ridges.segments
    xy = skel.ridges.xy
    nb = np.full((m, 2), -1, np.int64)
    sid = np.concatenate([seg[:, 0], seg[:, 1]])
    other = np.concatenate([seg[:, 1], seg[:, 0]])
    is_s = (sid >= n) & (sid < n + m)
    sid, other = sid[is_s] - n, other[is_s]
    order = np.argsort(sid, kind="stable")
    sid, other = sid[order], other[order]
    if sid.size:
        first = np.r_[True, sid[1:] != sid[:-1]]
        last = np.r_[sid[1:] != sid[:-1], True]
        nb[sid[first], 0] = other[first]
        nb[sid[last], 1] = other[last]
    sxy = skel.node_xyz[n:, :2]
    p0 = np.where(nb[:, :1] >= 0, xy[np.maximum(nb[:, 0], 0)], sxy)
    p1 = np.where(nb[:, 1:] >= 0, xy[np.maximum(nb[:, 1], 0)], sxy)
    d = p1 - p0
    norm = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-12)
    return -d[:, 1] / norm, d[:, 0] / norm


def _pass_violations(own: np.ndarray, z: np.ndarray, parent: np.ndarray, height: np.ndarray, depth: np.ndarray,
                     n: int, tol: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_kernels.pass_violations` on two cores: the E and SW neighbours on a second thread, the S
    and SE ones here, concatenated in that order (the same arrays as one call)."""
    with ThreadPoolExecutor(1, thread_name_prefix="orokit-passes") as pool:
        first = pool.submit(_kernels.pass_violations, own, z, parent, height, depth, n, tol, 0, 2)
        ia2, ib2, bn2, _ = _kernels.pass_violations(own, z, parent, height, depth, n, tol, 2, 4)
        ia1, ib1, bn1, _ = first.result()
    return np.concatenate([ia1, ia2]), np.concatenate([ib1, ib2]), np.concatenate([bn1, bn2])


def enforce_orometry(z: np.ndarray, grid: Grid, skel: TerrainSkeleton, *, label: np.ndarray | None = None,
                     drop_m: float = 0.5, trench_m: float = 3000.0, trench_slope: float = 0.0,
                     trench_depth_m: float = 0.0, keep_hills_m: float = 0.0, cut_slope: float = 0.0,
                     cut_depth_m: float = 0.0, max_rounds: int = 6) -> np.ndarray:
    """Make the raster's orometry that of the tree (in place).

    1. A trench perpendicular to the ridge through every saddle, just below it, until the
       ground is lower (no path beside a saddle crosses the ridge above it); a trench
       stops at a cell of another ridge (``label``: tree edge id of burnt ridge cells)
       and descends from the saddle at ``trench_slope`` (m/m) down to ``trench_depth_m``
       below it.
    2. Peak and saddle cells get their exact elevations.
    3. Rounds of basin checks (:func:`cap_basins`): hills without a tree peak that rise
       ``keep_hills_m`` or more above their pass (or above the tree peak they drain to)
       are cut down to their pass with a strictly ascending path (1 mm per cell) to a
       tree peak (with ``cut_slope`` > 0 the cut falls away from the pass at that slope, down to
       ``cut_depth_m`` below it: a shallow bowl, not a flat shelf); lower hills are kept (they cannot be peaks of prominence
       ``>= keep_hills_m``); every pass between the basins of two tree peaks that is
       higher than the tree's bottleneck between them (the lowest saddle on the tree
       path) is lowered ``drop_m`` below it, so the raster's Divide Tree at a prominence
       above ``keep_hills_m`` is the tree.
    """
    n = skel.n_peaks
    nodes = skel.node_xyz
    if nodes.shape[0] > n:
        nxv, nyv = _saddle_normals(skel)
        s = nodes[n:]
        _kernels.carve_saddles(z, float(grid.x0), float(grid.y0), float(grid.cell_size_m),
                               np.ascontiguousarray(s[:, 0]), np.ascontiguousarray(s[:, 1]),
                               np.ascontiguousarray(s[:, 2]), nxv, nyv, float(trench_m), float(drop_m),
                               label if label is not None else np.full(z.shape, -1, np.int32), float(trench_slope),
                               float(trench_depth_m))
    set_cells(z, grid, nodes[:, :2], nodes[:, 2])
    # ridge cells may be lowered down to their own saddle, peak and saddle cells never
    floor = np.full(z.shape, -np.inf, np.float32)
    if label is not None and nodes.shape[0] > n:
        on = label >= 0
        floor[on] = nodes[n + label[on], 2]
    row, col, ok = grid.cell_of(nodes[:, :2])
    floor[row[ok], col[ok]] = np.inf
    cap_basins(z, grid, skel, floor=floor, drop_m=drop_m, keep_hills_m=keep_hills_m, cut_slope=cut_slope,
               cut_depth_m=cut_depth_m, max_rounds=max_rounds)
    set_cells(z, grid, nodes[:, :2], nodes[:, 2])
    return z


def _border_pairs(owner: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Flat indices ``(a, b)`` of 8-adjacent cells whose ``owner`` differs (both >= 0)
    (:func:`_kernels.border_pairs`: offsets E, SW, S, SE, each in raster order)."""
    return _kernels.border_pairs(np.ascontiguousarray(owner, np.int64))


def _cut_mask(sp: np.ndarray, keep: np.ndarray, lab: np.ndarray) -> np.ndarray:
    """The cells of the spurious basins (``sp``) that are not kept (``keep`` per basin label, ``lab`` flat):
    ``sp`` itself when no hill is kept (always without ``keep_hills_m``: no pass over the raster, ~0.4 CPU s
    at 9 M cells over the rounds; :func:`_kernels.reconstruct_masked` never writes its mask)."""
    if not keep.any():
        return sp
    return sp & ~keep[np.maximum(lab, 0)].reshape(sp.shape)


class _Basins:
    """Basins of steepest ascent of a raster and the tree peak owning each, kept up to date as cells change.

    Labelled once with the orometry engine's kernel (:func:`~orokit.topology._kernels.ascent_labels`, as
    :func:`~orokit.topology.engine.steepest_ascent_basins`); after a change
    only the cells whose ascent chain the change can reach are relabelled
    (:func:`_kernels.update_basins`), so every cell keeps the owner a full relabelling gives
    (basin ids differ: a vanished maximum's id is left unused, a new one gets the next id).
    """

    def __init__(self, z: np.ndarray, cells: np.ndarray, pid: np.ndarray) -> None:
        self.z, self.cells, self.pid = z, np.ascontiguousarray(cells, np.int64), np.ascontiguousarray(pid, np.int64)
        # the engine's labels (:func:`steepest_ascent_basins`) and the pointers they follow, from one pass
        self.lab = np.empty(z.size, np.int64)
        self.ptr = np.empty(z.size, np.int64)
        self.top = ascent_labels(np.ascontiguousarray(z), self.lab, self.ptr)
        k = np.minimum(np.searchsorted(cells, self.top), cells.size - 1)
        self.tid = np.where(cells[k] == self.top, pid[k], -1).astype(np.int64)
        self.own = _kernels.basin_owner(self.lab, self.tid)

    def relabel(self, cells: np.ndarray) -> np.ndarray:
        """Relabel after whole basins (``cells``, flat; tree peak cells never among them) were lowered;
        returns the relabelled cells (no other cell's owner changed).

        Any other cell pointing into them would belong to them, except a tree peak cell in a spurious
        basin (kept out of the cut): those are relabelled too, and no other cell changes basin
        (:func:`_kernels.relabel_basins`)."""
        cells = np.concatenate([np.asarray(cells, np.int64), self.cells[self.own[self.cells] == -1]])
        self._add(_kernels.relabel_basins(self.z, self.ptr, self.lab, self.own, self.tid, cells, self.cells,
                                          self.pid))
        return cells

    def _add(self, new: tuple[np.ndarray, np.ndarray]) -> None:
        top, tid = new
        if top.size:
            self.top = np.concatenate([self.top, top])
            self.tid = np.concatenate([self.tid, tid])

    def update(self, changed: np.ndarray) -> np.ndarray:
        """Relabel after the cells ``changed`` (flat indices) of the raster changed; returns the
        relabelled cells (no other cell's owner changed)."""
        if changed.size == 0:
            return np.empty(0, np.int64)
        top, tid, cells = _kernels.update_basins(self.z, self.ptr, self.lab, self.own, self.tid,
                                                 np.ascontiguousarray(changed, np.int64), self.cells, self.pid)
        self._add((top, tid))
        return cells


def cap_basins(z: np.ndarray, grid: Grid, skel: TerrainSkeleton, *, floor: np.ndarray, drop_m: float = 0.5,
               keep_hills_m: float = 0.0, cut_slope: float = 0.0, cut_depth_m: float = 0.0,
               max_rounds: int = 6) -> dict[str, int]:
    """Rounds of spurious-hill cutting and pass capping on the raster's own basins (in place).

    The basins of steepest ascent are labelled once with the orometry engine's own
    kernels (:func:`orokit.topology.engine.steepest_ascent_basins`' kernel, so the total order and
    tie-breaks are the engine's) and kept up to date after every cut and cap (:class:`_Basins`:
    only the cells whose ascent the change reaches are relabelled). A basin whose maximum is not a tree
    peak is a spurious hill: its pass (best path from tree-owned ground) and the tree
    peak that path comes from are found by a flood (:func:`_kernels.flood_levels`). Hills
    whose top is less than ``keep_hills_m`` above their pass and below that tree peak are
    kept and join its basin (their prominence is below ``keep_hills_m``); the others are
    cut down (flooded from their outside with a 1 mm per cell ascent, or ``cut_slope`` per metre
    down to ``cut_depth_m`` below their pass: :func:`_kernels.reconstruct_masked`; a cut never takes a cell
    below its ``floor``, so a bowl on a crest never opens a pass below the crest's saddle). Then every pair of
    8-adjacent cells in the basins of two tree peaks whose pass (the lower of the two) is
    above the tree's bottleneck between the peaks (lowest saddle on the tree path) is
    lowered ``drop_m`` below it: the lower cell, or the higher one when the target is below
    the lower cell's ``floor`` (a ridge cell's own saddle elevation, +inf at peaks and
    saddles). Stops when a round changes nothing. ``z`` must be C-contiguous. Returns
    counters (rounds, cells cut, hills kept, cells capped, border pairs left above their
    bottleneck).
    """
    if not z.flags.c_contiguous:
        raise ValueError("cap_basins works in place on a C-contiguous array; pass np.ascontiguousarray(z)")
    if z.dtype != np.float32:
        raise ValueError(f"cap_basins works in place on float32 elevations (got {z.dtype}); pass z.astype(np.float32)")
    n = skel.n_peaks
    nodes = skel.node_xyz
    e = skel.edges if skel.edges is not None else np.empty((0, 3), np.int64)
    parent, height, depth = _kernels.merge_tree(
        n, e[:, 0].astype(np.int64), e[:, 1].astype(np.int64),
        nodes[n + e[:, 2], 2].astype(np.float64) if e.size else np.empty(0))
    row, col, ok = grid.cell_of(nodes[:n, :2])
    pid = np.flatnonzero(ok)
    pid = pid[np.argsort(nodes[pid, 2], kind="stable")]  # the highest peak of a shared cell wins
    cells = row[pid] * grid.nx + col[pid]
    order = np.argsort(cells, kind="stable")
    cells, pid = cells[order], pid[order]
    last = np.r_[cells[1:] != cells[:-1], True] if cells.size else np.zeros(0, bool)
    cells, pid = cells[last], pid[last]
    peak_z = nodes[:n, 2]
    zf = z.reshape(-1)
    ff = floor.reshape(-1)
    stats = {"rounds": 0, "cut": 0, "kept": 0, "capped": 0, "left": 0}

    if cells.size == 0:
        return stats

    basins = _Basins(z, cells, pid)

    def owners() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Tree peak owning each cell's basin (-1: a spurious maximum, -2: NaN), basin labels, basin tops."""
        return basins.own.reshape(z.shape), basins.lab, basins.top

    def spurious_hills(own: np.ndarray, lab: np.ndarray, top: np.ndarray):
        """Mask of spurious basins, the tree peak each drains to and whether it is kept."""
        sp = own == -1
        sp.reshape(-1)[cells] = False  # tree peaks seed the flood, never lowered
        if not sp.any() or keep_hills_m <= 0:  # nothing to keep: no flood needed, every hill is cut
            return sp, np.full(top.size, -1, np.int64), np.zeros(top.size, bool)
        level, source = _kernels.flood_levels(z, sp, own)
        lv, src = level.reshape(-1)[top], source.reshape(-1)[top]
        keep = (src >= 0) & (zf[top] - lv < keep_hills_m) & (zf[top] < peak_z[np.maximum(src, 0)])
        return sp, src, keep

    # the cells whose owner or elevation changed since the last pass check (None: check every pair); kept
    # hills get their owner from a flood of the whole raster each round, so with them every round checks all
    changed: list[np.ndarray] | None = None
    for _ in range(max_rounds):
        stats["rounds"] += 1
        own, lab, top = owners()
        cut = 0
        sp, src, keep = spurious_hills(own, lab, top)
        if sp.any():
            cutting = _cut_mask(sp, keep, lab)
            if cutting.any():
                cut = _kernels.reconstruct_masked(z, cutting, 1e-3, cut_slope * grid.cell_size_m, cut_depth_m)
                # a cut's bowl never takes a ridge cell below its own saddle (its floor): a bowl on a crest that
                # falls gently to its saddle would open a pass below the tree's saddle
                np.maximum(z, floor, out=z, where=cutting & np.isfinite(floor))
                stats["cut"] += cut
                # only the cut basins' cells can change basin (and elevation)
                relabelled = basins.relabel(np.flatnonzero(cutting))
                if changed is not None:
                    changed.append(relabelled)
                own, lab, top = owners()
                sp, src, keep = spurious_hills(own, lab, top)
        if sp.any() and keep_hills_m > 0:
            # kept hills join the basin of the tree peak their pass leads to (a sound owner: every
            # cell ascends to the hill top, whose best path out reaches that basin)
            stats["kept"] = int(np.unique(lab[sp.reshape(-1)]).size)
            own = np.where(sp, src[np.maximum(lab, 0)].reshape(z.shape), own)
        # border pairs (_border_pairs) whose pass is above the tree's bottleneck (-inf: separate trees):
        # after the first round only the pairs at a changed cell are checked again (the same pairs)
        if changed is None:
            ia, ib, bn = _pass_violations(np.ascontiguousarray(own, np.int64), z, parent, height, depth, n, 1e-3)
        else:
            ia, ib, bn = _kernels.pass_violations_near(np.ascontiguousarray(own, np.int64), z, parent, height,
                                                       depth, 1e-3, np.concatenate([np.empty(0, np.int64), *changed]),
                                                       ia, ib, bn)
        changed = None if keep_hills_m > 0 else []
        stats["left"] = int(ia.size)
        if not ia.size:
            break
        za, zb, target = zf[ia].astype(np.float64), zf[ib].astype(np.float64), bn - drop_m
        low = np.where(za <= zb, ia, ib)
        high = np.where(za <= zb, ib, ia)
        # a cell may go down to max(target, its floor) if that floor is not above the bottleneck
        # (ridge cells of the saddle itself end at the saddle's height: a tie, not a bypass)
        lim = (bn + 1e-4).astype(zf.dtype)
        pick = np.where(ff[low] <= lim, low, np.where(ff[high] <= lim, high, -1))
        keep_pair = pick >= 0
        pick = pick[keep_pair]
        before = zf[pick]
        np.minimum.at(zf, pick, np.maximum(target[keep_pair].astype(zf.dtype), ff[pick]))
        lowered = pick[zf[pick].view(np.uint32) != before.view(np.uint32)]
        relabelled = basins.update(lowered)
        if changed is not None:
            changed += [lowered, relabelled]
        stats["capped"] += int(keep_pair.sum())
        if not keep_pair.any() and cut == 0:
            break
    logger.debug("basin capping: %s", stats)
    return stats
