"""Numerical kernels of Divide Tree synthesis (arrays and scalars only).

The dart-throwing loop is sequential by nature (each accepted peak changes the
isolation of every later candidate), so it is compiled with numba instead of being
vectorised with numpy; placed peaks are kept in a uniform grid hash so the nearest
higher peak of a candidate is found in O(1) expected time.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def _cell_of(x, y, gx0, gy0, gcell, gnx, gny):
    ci = int((x - gx0) / gcell)
    cj = int((y - gy0) / gcell)
    if ci < 0:
        ci = 0
    if ci >= gnx:
        ci = gnx - 1
    if cj < 0:
        cj = 0
    if cj >= gny:
        cj = gny - 1
    return ci, cj


@njit(cache=True)
def _scan_cell(ii, jj, gnx, gny, head, nxt, px, py, qx, qy, best, bi):
    if ii < 0 or jj < 0 or ii >= gnx or jj >= gny:
        return best, bi
    k = head[jj * gnx + ii]
    while k >= 0:
        d2 = (px[k] - qx) ** 2 + (py[k] - qy) ** 2
        if d2 < best:
            best = d2
            bi = k
        k = nxt[k]
    return best, bi


@njit(cache=True)
def nearest_placed(qx, qy, px, py, n_placed, head, nxt, gx0, gy0, gcell, gnx, gny):
    """Nearest placed peak to (qx, qy): (index, distance); (-1, inf) when none."""
    best = np.inf
    bi = -1
    if n_placed == 0:
        return bi, best
    if n_placed < 48:
        for k in range(n_placed):
            d2 = (px[k] - qx) ** 2 + (py[k] - qy) ** 2
            if d2 < best:
                best = d2
                bi = k
        return bi, math.sqrt(best)
    ci, cj = _cell_of(qx, qy, gx0, gy0, gcell, gnx, gny)
    rmax = max(gnx, gny)
    r = 0
    while r <= rmax:
        if r == 0:
            best, bi = _scan_cell(ci, cj, gnx, gny, head, nxt, px, py, qx, qy, best, bi)
        else:
            for ii in range(ci - r, ci + r + 1):
                best, bi = _scan_cell(ii, cj - r, gnx, gny, head, nxt, px, py, qx, qy, best, bi)
                best, bi = _scan_cell(ii, cj + r, gnx, gny, head, nxt, px, py, qx, qy, best, bi)
            for jj in range(cj - r + 1, cj + r):
                best, bi = _scan_cell(ci - r, jj, gnx, gny, head, nxt, px, py, qx, qy, best, bi)
                best, bi = _scan_cell(ci + r, jj, gnx, gny, head, nxt, px, py, qx, qy, best, bi)
        if bi >= 0 and r * gcell >= math.sqrt(best):
            break
        r += 1
    return bi, math.sqrt(best)


@njit(cache=True)
def _bin(v, edges, open_last):
    nb = edges.size - 1
    if not (v >= edges[0]):
        return -1
    if v >= edges[nb]:
        if open_last or v == edges[nb]:
            return nb - 1
        return -1
    lo = 0
    hi = nb
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if edges[mid] <= v:
            lo = mid
        else:
            hi = mid
    return lo


@njit(cache=True)
def _disk_gain(qx, qy, cx0, cy0, cstep, cnx, cny, covered, radius, mark):
    """Uncovered disk centres within ``radius`` of (qx, qy); with ``mark`` they become covered."""
    if cnx == 0 or cny == 0:
        return 0
    i0 = max(0, int(math.ceil((qx - radius - cx0) / cstep)))
    i1 = min(cnx - 1, int(math.floor((qx + radius - cx0) / cstep)))
    j0 = max(0, int(math.ceil((qy - radius - cy0) / cstep)))
    j1 = min(cny - 1, int(math.floor((qy + radius - cy0) / cstep)))
    r2 = radius * radius
    g = 0
    for j in range(j0, j1 + 1):
        dy = cy0 + j * cstep - qy
        for i in range(i0, i1 + 1):
            if covered[j * cnx + i]:
                continue
            dx = cx0 + i * cstep - qx
            if dx * dx + dy * dy <= r2:
                g += 1
                if mark:
                    covered[j * cnx + i] = True
    return g


@njit(cache=True)
def _count_deficit(qx, qy, cx0, cy0, cstep, cnx, cny, target, have, frac, radius):
    """Mean over the disk centres within ``radius`` of (qx, qy) of ``(frac T - have) / sqrt(frac T + 1)``
    (T = ``target``): > 0 where the disks around hold fewer peaks than their share so far."""
    if cnx == 0 or cny == 0 or target.size == 0:
        return 0.0
    i0 = max(0, int(math.ceil((qx - radius - cx0) / cstep)))
    i1 = min(cnx - 1, int(math.floor((qx + radius - cx0) / cstep)))
    j0 = max(0, int(math.ceil((qy - radius - cy0) / cstep)))
    j1 = min(cny - 1, int(math.floor((qy + radius - cy0) / cstep)))
    r2 = radius * radius
    s = 0.0
    n = 0
    for j in range(j0, j1 + 1):
        dy = cy0 + j * cstep - qy
        for i in range(i0, i1 + 1):
            dx = cx0 + i * cstep - qx
            if dx * dx + dy * dy <= r2:
                e = frac * target[j * cnx + i]
                s += (e - have[j * cnx + i]) / math.sqrt(e + 1.0)
                n += 1
    return s / n if n > 0 else 0.0


@njit(cache=True)
def _count_add(qx, qy, cx0, cy0, cstep, cnx, cny, have, radius):
    """One more peak in every disk whose centre lies within ``radius`` of (qx, qy)."""
    if cnx == 0 or cny == 0 or have.size == 0:
        return
    i0 = max(0, int(math.ceil((qx - radius - cx0) / cstep)))
    i1 = min(cnx - 1, int(math.floor((qx + radius - cx0) / cstep)))
    j0 = max(0, int(math.ceil((qy - radius - cy0) / cstep)))
    j1 = min(cny - 1, int(math.floor((qy + radius - cy0) / cstep)))
    r2 = radius * radius
    for j in range(j0, j1 + 1):
        dy = cy0 + j * cstep - qy
        for i in range(i0, i1 + 1):
            dx = cx0 + i * cstep - qx
            if dx * dx + dy * dy <= r2:
                have[j * cnx + i] += 1.0


@njit(cache=True)
def _dip_bin(h, qx, qy, grid, gx0, gytop, gcx, gcy, thr):
    """1 when ``grid`` at (qx, qy) (rows from the north edge ``gytop``) stands ``thr`` or more above ``h``, else 0."""
    ny, nx = grid.shape
    col = min(max(int((qx - gx0) / gcx), 0), nx - 1)
    row = min(max(int((gytop - qy) / gcy), 0), ny - 1)
    v = grid[row, col]
    return 1 if np.isfinite(v) and v - h >= thr else 0

@njit(cache=True)
def throw_darts(
    px, py, z, n_start, n_end,
    fixed, fx, fy,
    cand_x, cand_y, cand_w,
    ptype, u,
    dist_edges, dist_ne, dist_open, dist_target, dist_have,
    dir_edges, dir_ne, dir_target, dir_have,
    head, nxt, gx0, gy0, gcell, gnx, gny,
    floor_w,
    cx0, cy0, cstep, cnx, cny, covered, n_covered, cover_target, radius, disk_w,
    grad_edges, grad_ne, grad_open, grad_target, grad_have, grad_on,
    kx0, ky0, kstep, knx, kny, count_target, count_have, count_w,
    dip_grid, dip_x0, dip_ytop, dip_cx, dip_cy, dip_thr, dip_target, dip_have, dip_on,
):
    """Place peaks ``n_start..n_end-1`` (sorted by decreasing elevation) by dart throwing.

    Every peak chooses one of its ``M`` candidate positions (drawn from the density
    map ``C_P`` beforehand) with probability proportional to ``cand_w`` (the ``C_H``
    Gaussian term) times the *remaining demand* of its isolation-distance bin and of
    its isolation-direction bin (target count minus peaks already placed in the bin,
    plus ``floor_w`` times the target). All already placed peaks are higher, so the
    nearest placed peak is the isolation target. ``dist_have``/``dir_have`` and the
    grid hash (``head``/``nxt``) are updated in place. Fixed peaks go to ``fx, fy``.

    Per-disk target (``disk_w > 0``): disk centres on a grid (``cx0, cy0, cstep, cnx,
    cny``) are *covered* once a peak lies within ``radius``; after peak ``k`` the number of
    covered centres should be ``cover_target[k]``. Each candidate's weight is multiplied by
    ``exp(-disk_w |gain - demand| / A)``, gain = centres it would cover, demand = target
    minus covered (at least 0), A = centres per disk. ``covered`` and ``n_covered[0]`` are
    updated in place.

    Gradient target (``grad_on[t]``): the candidate's weight is also multiplied by the
    remaining demand of its bin of ``(z_nearest - z) / d``, the elevation gradient to its
    nearest (higher) placed peak, as for the isolation bins (``grad_have`` updated in place).

    Per-disk peak count (``count_w > 0``; centres on their own grid ``kx0, ky0, kstep, knx, kny``,
    covering the whole domain): disk centre ``c`` should end with ``count_target[c]`` peaks within
    ``radius``; after peak ``k`` of ``n`` it should hold
    ``f = (k + 1) / n`` of them. A candidate's weight is multiplied by ``exp(count_w D)``, D the
    mean of ``(f T - have) / sqrt(f T + 1)`` over the centres within ``radius`` of it (clipped to
    [-3, 3]); ``count_have`` is updated in place.

    Forced-tail target (``dip_on[t]``): a candidate on a ridge of the earlier passes splits it, and the lower
    peaks placed there force a prominence of ``dip_grid`` (the ridge's lower end, rows from the north edge
    ``dip_ytop``) minus ``z`` on that end. Dips from ``dip_thr[t]`` up fill bin 1, the others bin 0; the
    candidate's weight is multiplied by the remaining demand of its bin (``dip_target[t]`` minus
    ``dip_have[t]``, updated in place, plus ``floor_w`` times the target).
    Returns per placed peak the isolation distance (NaN for the first).
    """
    m = cand_x.shape[1]
    iso = np.full(n_end - n_start, np.nan)
    w = np.empty(m)
    n_centres = cnx * cny
    per_disk = math.pi * radius * radius / (cstep * cstep) if cstep > 0 else 1.0
    use_count = count_w > 0 and count_target.size == knx * kny and count_target.size > 0
    n_all = z.size
    for k in range(n_start, n_end):
        r = k - n_start
        t = ptype[k]
        if fixed[k]:
            qx = fx[k]
            qy = fy[k]
            nb, d = nearest_placed(qx, qy, px, py, k, head, nxt, gx0, gy0, gcell, gnx, gny)
            choice_d = d
            choice_nb = nb
        else:
            total = 0.0
            best_base = -1.0
            best_c = 0
            use_disks = disk_w > 0 and n_covered[0] < n_centres
            demand = max(cover_target[k] - n_covered[0], 0.0)
            for c in range(m):
                qx = cand_x[r, c]
                qy = cand_y[r, c]
                nb, d = nearest_placed(qx, qy, px, py, k, head, nxt, gx0, gy0, gcell, gnx, gny)
                wc = cand_w[r, c]
                if wc > best_base:
                    best_base = wc
                    best_c = c
                if nb >= 0:
                    b1 = _bin(d, dist_edges[t, : dist_ne[t]], dist_open[t])
                    ang = math.degrees(math.atan2(py[nb] - qy, px[nb] - qx))
                    if ang < 0:
                        ang += 360.0
                    b2 = _bin(ang, dir_edges[t, : dir_ne[t]], False)
                    if b1 >= 0:
                        f1 = max(dist_target[t, b1] - dist_have[t, b1], 0.0) + floor_w * dist_target[t, b1]
                    else:
                        f1 = floor_w * 0.1
                    f2 = 1.0
                    if b2 >= 0:
                        f2 = max(dir_target[t, b2] - dir_have[t, b2], 0.0) + floor_w * dir_target[t, b2]
                    wc = wc * f1 * f2
                    if grad_on[t]:
                        b3 = _bin((z[nb] - z[k]) / max(d, 1e-9), grad_edges[t, : grad_ne[t]], grad_open[t])
                        if b3 >= 0:
                            wc = wc * (max(grad_target[t, b3] - grad_have[t, b3], 0.0)
                                       + floor_w * grad_target[t, b3])
                        else:
                            wc = wc * floor_w * 0.1
                    if dip_on[t]:
                        b4 = _dip_bin(z[k], qx, qy, dip_grid, dip_x0, dip_ytop, dip_cx, dip_cy, dip_thr[t])
                        wc = wc * (max(dip_target[t, b4] - dip_have[t, b4], 0.0) + floor_w * dip_target[t, b4])
                if use_disks:
                    gain = _disk_gain(qx, qy, cx0, cy0, cstep, cnx, cny, covered, radius, False)
                    wc = wc * math.exp(-disk_w * abs(gain - demand) / per_disk)
                if use_count:
                    dc = _count_deficit(qx, qy, kx0, ky0, kstep, knx, kny, count_target, count_have,
                                        (k + 1.0) / n_all, radius)
                    wc = wc * math.exp(count_w * min(max(dc, -3.0), 3.0))
                w[c] = wc
                total += wc
            if total > 0:
                thr = u[k] * total
                acc = 0.0
                pick = m - 1
                for c in range(m):
                    acc += w[c]
                    if acc >= thr and w[c] > 0:
                        pick = c
                        break
            else:
                pick = best_c
            qx = cand_x[r, pick]
            qy = cand_y[r, pick]
            nb, d = nearest_placed(qx, qy, px, py, k, head, nxt, gx0, gy0, gcell, gnx, gny)
            choice_d = d
            choice_nb = nb
        px[k] = qx
        py[k] = qy
        if choice_nb >= 0:
            iso[r] = choice_d
            b1 = _bin(choice_d, dist_edges[t, : dist_ne[t]], dist_open[t])
            if b1 >= 0:
                dist_have[t, b1] += 1.0
            ang = math.degrees(math.atan2(py[choice_nb] - qy, px[choice_nb] - qx))
            if ang < 0:
                ang += 360.0
            b2 = _bin(ang, dir_edges[t, : dir_ne[t]], False)
            if b2 >= 0:
                dir_have[t, b2] += 1.0
            if grad_on[t]:
                b3 = _bin((z[choice_nb] - z[k]) / max(choice_d, 1e-9), grad_edges[t, : grad_ne[t]], grad_open[t])
                if b3 >= 0:
                    grad_have[t, b3] += 1.0
            if dip_on[t]:
                b4 = _dip_bin(z[k], qx, qy, dip_grid, dip_x0, dip_ytop, dip_cx, dip_cy, dip_thr[t])
                dip_have[t, b4] += 1.0
        if n_covered[0] < n_centres:
            n_covered[0] += _disk_gain(qx, qy, cx0, cy0, cstep, cnx, cny, covered, radius, True)
        if use_count:
            _count_add(qx, qy, kx0, ky0, kstep, knx, kny, count_have, radius)
        ci, cj = _cell_of(qx, qy, gx0, gy0, gcell, gnx, gny)
        cell = cj * gnx + ci
        nxt[k] = head[cell]
        head[cell] = k
    return iso
