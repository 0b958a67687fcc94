"""Multi-pass dart throwing of peaks (Argudo et al. 2019, sections 5.1 and 5.3).

Peaks are sorted by decreasing elevation and placed highest first. The ranks are
split into passes, each holding twice as many peaks as the previous one; earlier
peaks stay fixed, and the ridges of the tree built after each pass are diffused into
the density map so the next, lower peaks land near them.
"""
from __future__ import annotations

import logging
import math

import numpy as np
from scipy.ndimage import gaussian_filter

from orokit._typing import SeedLike
from orokit.synthesis import _kernels
from orokit.synthesis.controls import ControlMaps, Domain
from orokit.synthesis.disks import disk_centres

logger = logging.getLogger(__name__)

__all__ = ["pass_bounds", "draw_candidates", "ridge_density", "ridge_end_grid", "void_density", "place_peaks", "disk_count_targets"]


def pass_bounds(n: int, n_passes: int) -> list[tuple[int, int]]:
    """Rank ranges of the passes: sizes ``n0, 2 n0, 4 n0, ...`` summing to ``n``."""
    n_passes = max(1, min(int(n_passes), max(1, n)))
    n0 = n / (2**n_passes - 1)
    ends = [int(round(n0 * (2 ** (k + 1) - 1))) for k in range(n_passes)]
    ends[-1] = n
    out, start = [], 0
    for e in ends:
        e = max(e, start)
        if e > start:
            out.append((start, e))
        start = e
    return out


def draw_candidates(
    weights: np.ndarray, domain: Domain, count: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``count`` points drawn with density proportional to the grid ``weights``.

    Returns x, y and the grid row/col of every point (uniform inside cells).
    """
    flat = weights.ravel()
    cdf = np.cumsum(flat)
    cell = np.searchsorted(cdf, rng.random(count) * cdf[-1], side="right")
    cell = np.minimum(cell, flat.size - 1)
    row, col = np.divmod(cell, weights.shape[1])
    cx, cy = domain.cell
    x = domain.x0 + (col + rng.random(count)) * cx
    y = domain.y0 + domain.height - (row + rng.random(count)) * cy
    return x, y, row, col


def _ridge_cells(x: np.ndarray, y: np.ndarray, a: np.ndarray, b: np.ndarray,
                 domain: Domain) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Grid row, col of points every half cell along each ridge ``a``-``b``, and the ridge of each point."""
    cx, cy = domain.cell
    step = 0.5 * min(cx, cy)
    length = np.hypot(x[b] - x[a], y[b] - y[a])
    k = np.maximum(2, np.ceil(length / step).astype(np.int64) + 1)
    e = np.repeat(np.arange(a.size), k)
    t = np.concatenate([np.linspace(0, 1, kk) for kk in k]) if a.size < 64 else _ramp(k)
    sx = x[a][e] + t * (x[b] - x[a])[e]
    sy = y[a][e] + t * (y[b] - y[a])[e]
    row, col = domain.cell_index(sx, sy)
    return row, col, e


def ridge_density(x: np.ndarray, y: np.ndarray, a: np.ndarray, b: np.ndarray, domain: Domain,
                  sigma_m: float) -> np.ndarray:
    """Ridges rasterised on the domain grid and blurred (Gaussian of ``sigma_m``), max 1."""
    grid = np.zeros(domain.shape)
    if a.size:
        cx, cy = domain.cell
        row, col, _ = _ridge_cells(x, y, a, b, domain)
        np.add.at(grid, (row, col), 1.0)
        grid = gaussian_filter(grid, sigma=max(sigma_m / min(cx, cy), 0.5))
    m = grid.max()
    return grid / m if m > 0 else grid


def ridge_end_grid(x: np.ndarray, y: np.ndarray, z: np.ndarray, a: np.ndarray, b: np.ndarray, domain: Domain,
                reach_m: float) -> np.ndarray:
    """Per grid cell, the highest lower end (elevation, m) of the ridges passing within ``reach_m`` (NaN: none).

    A lower peak placed there splits that ridge: the tree's path from its lower end to higher ground then
    dips to the new peak, which forces the end a prominence of at least this minus the new peak's elevation
    (:func:`orokit.synthesis.saddles.forced_prominence`).
    """
    from scipy.ndimage import maximum_filter

    grid = np.full(domain.shape, -np.inf)
    if a.size:
        row, col, e = _ridge_cells(x, y, a, b, domain)
        np.maximum.at(grid, (row, col), np.minimum(z[a], z[b])[e])
        cx, cy = domain.cell
        ry, rx = max(int(reach_m // cy), 0), max(int(reach_m // cx), 0)
        oy, ox = np.ogrid[-ry: ry + 1, -rx: rx + 1]
        disk = (ox * cx) ** 2 + (oy * cy) ** 2 <= max(reach_m, 0.5 * min(cx, cy)) ** 2
        grid = maximum_filter(grid, footprint=disk, mode="constant", cval=-np.inf)
    return np.where(np.isfinite(grid), grid, np.nan)


def void_density(x: np.ndarray, y: np.ndarray, domain: Domain, sigma_m: float) -> np.ndarray:
    """``min(d / (4 sigma), 1)^2`` with d the distance of each grid cell to the nearest placed peak.

    Added to the ridge density between passes, it draws lower peaks into the holes the
    earlier passes left (without it the distance from a point to the nearest peak had a
    90th percentile 1.5 x the real trees', issue 11); ``4 sigma`` is twice the mean
    spacing of the peaks placed so far.
    """
    from scipy import ndimage

    free = np.ones(domain.shape, bool)
    if x.size:
        row, col = domain.cell_index(x, y)
        free[row, col] = False
    else:
        return np.ones(domain.shape)
    cx, cy = domain.cell
    d = ndimage.distance_transform_edt(free, sampling=(cy, cx))
    return np.clip(d / (4.0 * sigma_m), 0.0, 1.0) ** 2


def _ramp(k: np.ndarray) -> np.ndarray:
    """Concatenation of ``linspace(0, 1, k_i)`` for every k_i (vectorised)."""
    start = np.repeat(np.cumsum(k) - k, k)
    idx = np.arange(k.sum()) - start
    return idx / np.repeat(k - 1, k)


def place_peaks(
    z: np.ndarray,
    ptype: np.ndarray,
    fixed: np.ndarray,
    fxy: np.ndarray,
    controls: ControlMaps,
    domain: Domain,
    iso_dist: list,
    iso_dir: list,
    rho: np.ndarray,
    *,
    n_passes: int = 4,
    n_candidates: int = 96,
    ridge_floor: float = 0.15,
    floor_w: float = 0.05,
    forced: tuple[np.ndarray, np.ndarray] | None = None,
    void_weight: float = 0.0,
    disks: list | None = None,
    disk_weight: float = 0.0,
    disk_count_weight: float = 0.0,
    elevation_tolerance: float = 0.05,
    gradients: list | None = None,
    gradient_tail: float | None = None,
    forced_tails: list | None = None,
    rng: SeedLike = None,
) -> tuple[np.ndarray, np.ndarray, dict]:
    """Positions of peaks sorted by decreasing elevation ``z``.

    Parameters
    ----------
    z : elevations, sorted in decreasing order; ptype : terrain-type index per peak.
    fixed, fxy : peaks with a user-given position and that (n, 2) position.
    controls, domain : control maps and their grid.
    iso_dist, iso_dir : per type, isolation distance/direction histograms.
    rho : per-peak ridge exponent (for the ridges diffused between passes).
    void_weight : weight of :func:`void_density` beside the ridge density between passes
        (0: the paper's ridge density only).
    disks, disk_weight : per type, the ``disks`` record of its terrain type
        (:mod:`orokit.synthesis.disks`) and the strength of the per-disk target: the share of
        disk centres holding one of the highest peaks follows the type's ``top_rank``
        distribution (0, or a type without the record: off).
    disk_count_weight : strength of the per-disk peak count target: every disk centre draws a
        target count from the type's ``peaks`` quantiles (:func:`disk_count_targets`) and
        candidates are drawn towards disks short of their share (0, or a type without the
        record: off; nothing is drawn from ``rng`` then).
    gradients : per type, the histogram of the elevation gradient from a peak to its nearest
        higher peak (:attr:`orokit.synthesis.terrain_type.TerrainType.gradient`), followed like
        the isolation histograms; None (for the list or a type): not followed.
    gradient_tail : the open last bin of each gradient histogram (values from the real tree's 99th
        percentile up) ends at this times its lower edge: a steeper candidate counts as out of range
        (None: open, any steepness fills that bin).
    forced_tails : per type, None or ``(share, threshold_m)``: the type's ``forced_tail`` and the prominence it
        is counted at (its 90th percentile). A candidate within half the pass's spacing of a ridge of the earlier
        passes whose lower end stands ``threshold_m`` or more above the peak (:func:`ridge_end_grid`) would split
        it and force that prominence on the end; the share of the type's peaks placed so is followed like the
        isolation histograms, so once that share is used the passes' lower peaks go beside the higher ones, on
        their flanks, rather than into the low gaps on the ridges between them (None: off).

    Returns
    -------
    x, y, info (``passes``: rank ranges; ``disk_centres``: centres used by the per-disk target).
    """
    from orokit.synthesis.ridges import delaunay_mst

    rng = np.random.default_rng(rng)
    n = z.size
    n_types = len(iso_dist)
    px = np.zeros(n)
    py = np.zeros(n)
    fx = np.ascontiguousarray(fxy[:, 0], dtype=float)
    fy = np.ascontiguousarray(fxy[:, 1], dtype=float)
    # C_H acceptance: N(C_H(p) - h; sigma), sigma = elevation_tolerance x the C_H range
    ch = controls.elevation
    if ch is not None:
        rng_ch = float(np.nanmax(ch) - np.nanmin(ch))
        sigma = (rng_ch if rng_ch > 0 else max(float(np.ptp(z)), 20.0)) * elevation_tolerance
    # isolation targets per type: expected count per bin over the type's peaks
    counts_t = np.bincount(ptype, minlength=n_types).astype(float)
    ne_d = np.array([len(h.edges) for h in iso_dist], np.int64)
    ne_a = np.array([len(h.edges) for h in iso_dir], np.int64)
    de = np.full((n_types, ne_d.max()), np.inf)
    ae = np.full((n_types, ne_a.max()), np.inf)
    dt = np.zeros((n_types, ne_d.max() - 1))
    at = np.zeros((n_types, ne_a.max() - 1))
    dopen = np.zeros(n_types, np.bool_)
    for t in range(n_types):
        de[t, : ne_d[t]] = iso_dist[t].edges
        ae[t, : ne_a[t]] = iso_dir[t].edges
        dt[t, : ne_d[t] - 1] = iso_dist[t].probabilities() * max(counts_t[t] - 1, 0)
        at[t, : ne_a[t] - 1] = iso_dir[t].probabilities() * max(counts_t[t] - 1, 0)
        dopen[t] = iso_dist[t].open_last
    dh = np.zeros_like(dt)
    ah = np.zeros_like(at)
    grads = list(gradients) if gradients is not None else [None] * n_types
    ne_g = np.array([2 if h is None else len(h.edges) for h in grads], np.int64)
    ge = np.full((n_types, ne_g.max()), np.inf)
    gt = np.zeros((n_types, ne_g.max() - 1))
    gopen = np.zeros(n_types, np.bool_)
    gon = np.array([h is not None for h in grads], np.bool_)
    for t, h in enumerate(grads):
        if h is not None:
            ge[t, : ne_g[t]] = h.edges
            gt[t, : ne_g[t] - 1] = h.probabilities() * max(counts_t[t] - 1, 0)
            gopen[t] = h.open_last
            if h.open_last and gradient_tail is not None:
                ge[t, ne_g[t] - 1] = max(float(gradient_tail), 1.0) * h.edges[-1]
                gopen[t] = False
    gh = np.zeros_like(gt)
    dip_thr = np.full(n_types, np.inf)
    dip_target = np.zeros((n_types, 2))
    dip_on = np.zeros(n_types, np.bool_)
    dip_grid = np.full((1, 1), np.nan)
    if forced_tails is not None:
        for t, rec in enumerate(forced_tails):
            if rec is not None:
                share, threshold = float(rec[0]), float(rec[1])
                dip_thr[t] = threshold
                dip_target[t] = np.array([1.0 - share, share]) * max(counts_t[t] - 1, 0)
                dip_on[t] = True
    dip_have = np.zeros_like(dip_target)
    dip_cx, dip_cy = domain.cell
    # grid hash of placed peaks: cells about the final mean spacing
    spacing = np.sqrt(domain.width * domain.height / max(n, 1))
    gcell = max(spacing, 1e-6)
    gnx = int(np.ceil(domain.width / gcell)) + 1
    gny = int(np.ceil(domain.height / gcell)) + 1
    head = np.full(gnx * gny, -1, np.int64)
    nxt = np.full(n, -1, np.int64)
    u = rng.random(n)
    cover = _coverage_setup(disks, disk_weight, ptype, n_types, domain)
    count_grid: tuple = (0.0, 0.0, 1.0, 0, 0, np.zeros(0))
    if disk_count_weight > 0 and disks and len(disks) == n_types and all(d is not None for d in disks):
        radius = float(disks[0]["radius_m"])
        step = disk_centres((domain.x0, domain.y0, domain.x0 + domain.width, domain.y0 + domain.height),
                            radius)[2]
        kx0, ky0, knx, kny, target = disk_count_targets(disks, controls, domain, step, radius, rng, n)
        count_grid = (kx0, ky0, step, knx, kny, target)
    count_have = np.zeros(count_grid[5].size)
    density = controls.density.copy()
    type_masks = [controls.type_index == t for t in range(n_types)]
    passes = pass_bounds(n, n_passes)
    for p_i, (s, e) in enumerate(passes):
        cand_x = np.zeros((e - s, n_candidates))
        cand_y = np.zeros((e - s, n_candidates))
        cand_w = np.ones((e - s, n_candidates))
        for t in range(n_types):
            rows = np.flatnonzero((ptype[s:e] == t) & ~fixed[s:e])
            if rows.size == 0:
                continue
            wgrid = density * type_masks[t]
            if not (wgrid > 0).any():
                from orokit.errors import InputError

                raise InputError(f"terrain type {t} has no cell with density > 0 in the type map: no room for its peaks")
            x, y, r, c = draw_candidates(wgrid, domain, rows.size * n_candidates, rng)
            cand_x[rows] = x.reshape(rows.size, n_candidates)
            cand_y[rows] = y.reshape(rows.size, n_candidates)
            if ch is not None:
                chv = ch[r, c].reshape(rows.size, n_candidates)
                g = np.exp(-0.5 * ((chv - z[s:e][rows][:, None]) / sigma) ** 2)
                cand_w[rows] = np.where(np.isfinite(g), g, 1.0)
        _kernels.throw_darts(
            px, py, np.ascontiguousarray(z, dtype=float), s, e, fixed, fx, fy, cand_x, cand_y, cand_w, ptype.astype(np.int64), u,
            de, ne_d, dopen, dt, dh, ae, ne_a, at, ah, head, nxt,
            domain.x0, domain.y0, gcell, gnx, gny, floor_w, *cover, ge, ne_g, gopen, gt, gh, gon,
            *count_grid, count_have, float(disk_count_weight),
            dip_grid, domain.x0, domain.y0 + domain.height, dip_cx, dip_cy, dip_thr, dip_target, dip_have, dip_on,
        )
        if p_i + 1 < len(passes):
            fa = fb = None
            if forced is not None:
                keep = (forced[0] < e) & (forced[1] < e)
                fa, fb = forced[0][keep], forced[1][keep]
            a, b = delaunay_mst(px[:e], py[:e], z[:e], rho=rho[:e],
                                forced=None if fa is None or fb is None else (fa, fb))
            sigma_m = 0.5 * np.sqrt(domain.width * domain.height / e)
            dens_r = ridge_density(px[:e], py[:e], a, b, domain, sigma_m)
            if void_weight > 0:
                dens_r = dens_r + void_weight * void_density(px[:e], py[:e], domain, sigma_m)
                dens_r /= max(1.0, float(dens_r.max()))
            density = controls.density * (ridge_floor + (1 - ridge_floor) * dens_r)
            if dip_on.any():
                dip_grid = ridge_end_grid(px[:e], py[:e], z[:e], a, b, domain, sigma_m)
        logger.debug("pass %d: placed peaks %d..%d", p_i, s, e)
    info = {"passes": passes, "disk_centres": int(cover[3] * cover[4]) if cover[-1] > 0 else 0}
    if dip_on.any():
        info["forced_tail"] = {"target": dip_target, "placed": dip_have}
    if count_grid[5].size:
        info["disk_count"] = {"target": count_grid[5], "placed": count_have}
    return px, py, info


def disk_count_targets(disks: list, controls: ControlMaps, domain: Domain, step: float, radius: float,
                       rng: np.random.Generator, n: int | None = None) -> tuple[float, float, int, int, np.ndarray]:
    """Disk centres on a grid of ``step`` over the whole domain and their target peak counts.

    A Gaussian random field on the centres, smoothed over half the disk radius (the
    correlation of the counts of overlapping disks of a uniform random density), is mapped
    by rank onto the quantiles of the ``peaks`` record of the centre's type (the real disks'
    counts, so the twin's disks hold as many peaks as the real ones, not ``n`` spread evenly),
    times the density map ``C_P``'s mass in the disk (inside the domain) over a full disk's
    at the interior's mean density: a disk reaching past the border wants its inside share.
    With ``n`` (the peaks to place), the strip within ``radius`` of the border takes the
    density that the interior's (the record's mean count per disk area) leaves of ``n``
    (0.1 to 2 times the interior's): the real crops hold more of their peaks inside than
    an even spread (pyrenees: median 96 peaks per disk against 77 for ``n`` spread evenly).
    Returns x0, y0 (the south-west centre), nx, ny and the targets (row-major from the south).
    """
    from scipy.signal import fftconvolve

    nx = max(1, int(np.ceil(domain.width / step)))
    ny = max(1, int(np.ceil(domain.height / step)))
    x0 = domain.x0 + 0.5 * (domain.width - (nx - 1) * step)
    y0 = domain.y0 + 0.5 * (domain.height - (ny - 1) * step)
    field = gaussian_filter(rng.standard_normal((ny, nx)), sigma=max(0.5 * radius / step, 0.5))
    u = (np.argsort(np.argsort(field.ravel(), kind="stable"), kind="stable") + 0.5) / field.size
    x, y = (v.ravel() for v in np.meshgrid(x0 + np.arange(nx) * step, y0 + np.arange(ny) * step))
    row, col = domain.cell_index(x, y)
    ctype = controls.type_index[row, col]
    q = np.zeros(x.size)
    for t, d in enumerate(disks):
        mine = ctype == t
        if d is not None and mine.any():
            q[mine] = np.interp(u[mine], np.asarray(d["levels"], float), np.asarray(d["peaks"], float))
    cs_x, cs_y = domain.cell
    ky = np.arange(-int(radius // cs_y), int(radius // cs_y) + 1) * cs_y
    kx = np.arange(-int(radius // cs_x), int(radius // cs_x) + 1) * cs_x
    kernel = (kx[None, :] ** 2 + ky[:, None] ** 2 <= radius**2).astype(float)
    dens = np.clip(np.nan_to_num(controls.density), 0.0, None)
    gy_, gx_ = np.indices(dens.shape)
    bx = np.minimum(gx_ + 0.5, dens.shape[1] - gx_ - 0.5) * cs_x
    by = np.minimum(gy_ + 0.5, dens.shape[0] - gy_ - 0.5) * cs_y
    strip = np.minimum(bx, by) < radius
    if n is not None and strip.any() and (~strip).any() and q.mean() > 0:
        # the border strip holds what the interior's density leaves of the n peaks
        per_area = q.mean() / (math.pi * radius**2)
        a_in = float(dens[~strip].sum()) * cs_x * cs_y
        a_strip = float(dens[strip].sum()) * cs_x * cs_y
        share = float(np.clip((n - per_area * a_in) / max(per_area * a_strip, 1e-300), 0.1, 2.0))
        dens = np.where(strip, share * dens, dens)
    mass = np.clip(fftconvolve(dens, kernel, mode="same")[row, col], 0.0, None)
    full = float(kernel.sum() * (dens[~strip].mean() if (~strip).any() else dens.mean()))
    target = q * mass / full if full > 0 else np.zeros_like(q)
    return float(x0), float(y0), nx, ny, np.ascontiguousarray(target, dtype=float)


def _coverage_setup(disks: list | None, disk_weight: float, ptype: np.ndarray, n_types: int,
                    domain: Domain) -> tuple:
    """Kernel arguments of the per-disk target (all zero-sized when it is off)."""
    from orokit.synthesis.disks import coverage_targets, disk_centres

    n = ptype.size
    off = (0.0, 0.0, 1.0, 0, 0, np.zeros(0, np.bool_), np.zeros(1, np.int64), np.zeros(n), 1.0, 0.0)
    if disk_weight <= 0 or not disks or len(disks) != n_types or any(d is None for d in disks):
        return off
    radius = float(disks[0]["radius_m"])
    extent = (domain.x0, domain.y0, domain.x0 + domain.width, domain.y0 + domain.height)
    cx, cy, step = disk_centres(extent, radius)
    if cx.size == 0:
        return off
    nx = int(np.unique(cx).size)
    ny = cx.size // nx
    target = np.zeros(n)
    for t in range(n_types):
        mine = np.flatnonzero(ptype == t)  # peaks are sorted highest first: rank within the type
        target[mine] = coverage_targets(disks[t], mine.size) * cx.size
    return (float(cx.min()), float(cy.min()), float(step), nx, ny, np.zeros(cx.size, np.bool_),
            np.zeros(1, np.int64), target, radius, float(disk_weight))
