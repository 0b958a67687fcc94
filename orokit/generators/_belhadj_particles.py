"""Numba kernels of the Belhadj 2007 particle skeleton (§2): ridge routes and river particles.

Pure array code: positions are in cells (row, col as floats; cell (i, j) covers
``[i, i+1) x [j, j+1)``), elevations in metres. The public side is
:func:`orokit.generators.belhadj.particle_skeleton`.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

#: why a ridge particle stopped
STOP_BORDER, STOP_ALTITUDE, STOP_COLLISION, STOP_STEPS = 0, 1, 2, 3
#: fate of a river particle
RIVER_EXIT, RIVER_JOINED, RIVER_STATIC = 0, 1, 2


@njit(cache=True)
def ridge_route(owner, pid, r0, c0, theta, lateral, step, sigma, y0, base, floor_frac, rr, cc, alt):
    """Walk one ridge particle; mark its cells in ``owner`` with ``pid`` and return
    ``(n_cells, stop_reason)``; the route's cells go to ``rr, cc`` and altitudes to ``alt``.

    Position after ``i`` steps: ``P0 + i step u + lateral[i] n`` (``u`` the heading, ``n``
    its normal; ``lateral`` an fBm path, the paper's side impacts). Altitude at the
    covered distance ``s = i step``: ``base + (y0 - base) exp(-s^2 / 2 sigma^2)``.
    Segments between successive positions are sampled every quarter cell. The particle
    stops at the grid border, when its altitude above ``base`` falls below ``floor_frac``
    of ``y0 - base``, or before entering a cell of another particle's route
    (``owner >= 0`` and ``!= pid``).
    """
    ny, nx = owner.shape
    ur, uc = -math.sin(theta), math.cos(theta)  # north-up: row grows southwards
    nr, nc = uc, -ur
    k = 0
    pr, pc = r0, c0
    for i in range(1, lateral.size):
        s = i * step
        a = math.exp(-0.5 * (s / sigma) ** 2)
        if a < floor_frac:
            return k, STOP_ALTITUDE
        qr = r0 + s * ur + lateral[i] * nr
        qc = c0 + s * uc + lateral[i] * nc
        length = math.hypot(qr - pr, qc - pc)
        m = max(int(math.ceil(length * 4.0)), 1)
        for t in range(1, m + 1):
            f = t / m
            ri = math.floor(pr + f * (qr - pr))
            ci = math.floor(pc + f * (qc - pc))
            if ri < 0 or ri >= ny or ci < 0 or ci >= nx:
                return k, STOP_BORDER
            o = owner[ri, ci]
            if o >= 0 and o != pid:
                return k, STOP_COLLISION
            if o != pid:
                owner[ri, ci] = pid
                rr[k] = ri
                cc[k] = ci
                # altitude interpolated along the segment (covered distance)
                sf = (i - 1 + f) * step
                alt[k] = base + (y0 - base) * math.exp(-0.5 * (sf / sigma) ** 2)
                k += 1
        pr, pc = qr, qc
    return k, STOP_STEPS


@njit(cache=True)
def river_particles(h, r0, c0, mass0, gravity, friction, max_steps, min_speed, static_steps,
                    owner, path_r, path_c, path_n, fate, joins, mass):
    """Move all river particles together on the blended terrain ``h`` until each exits the
    grid, joins another particle's path, or stays static.

    Each step: ``a = -gravity grad h`` (bilinear gradient, metres per cell),
    ``v <- (1 - friction) v + a``, the move is clipped to one cell. A particle that enters
    a cell of another particle's path stops there (``fate = RIVER_JOINED``, ``joins`` =
    that particle; the paper's merge: the other one's mass and velocity gain its own if it
    still moves). Slower than ``min_speed`` for ``static_steps`` steps, or out of steps:
    ``RIVER_STATIC``. Path cells go to ``path_r/path_c[p, :path_n[p]]``; ``owner`` holds the
    particle of every visited cell (-1 none).
    """
    ny, nx = h.shape
    n = r0.size
    pr = r0.copy()
    pc = c0.copy()
    vr = np.zeros(n)
    vc = np.zeros(n)
    slow = np.zeros(n, np.int64)
    active = np.ones(n, np.bool_)
    for p in range(n):
        mass[p] = mass0[p]
        fate[p] = RIVER_STATIC
        joins[p] = -1
        path_n[p] = 0
        ri, ci = int(math.floor(pr[p])), int(math.floor(pc[p]))
        if owner[ri, ci] >= 0:  # starts on another path: joins it at once
            fate[p] = RIVER_JOINED
            joins[p] = owner[ri, ci]
            active[p] = False
            path_r[p, 0] = ri
            path_c[p, 0] = ci
            path_n[p] = 1
            continue
        owner[ri, ci] = p
        path_r[p, 0] = ri
        path_c[p, 0] = ci
        path_n[p] = 1
    for _ in range(max_steps):
        any_active = False
        for p in range(n):
            if not active[p]:
                continue
            any_active = True
            # bilinear gradient at the particle (cell centres at i + 0.5)
            y = min(max(pr[p] - 0.5, 0.0), ny - 1.000001)
            x = min(max(pc[p] - 0.5, 0.0), nx - 1.000001)
            i0 = min(int(y), ny - 2) if ny > 1 else 0
            j0 = min(int(x), nx - 2) if nx > 1 else 0
            fy = y - i0
            fx = x - j0
            i1 = min(i0 + 1, ny - 1)
            j1 = min(j0 + 1, nx - 1)
            gr = ((h[i1, j0] - h[i0, j0]) * (1 - fx) + (h[i1, j1] - h[i0, j1]) * fx)
            gc = ((h[i0, j1] - h[i0, j0]) * (1 - fy) + (h[i1, j1] - h[i1, j0]) * fy)
            vr[p] = (1.0 - friction) * vr[p] - gravity * gr
            vc[p] = (1.0 - friction) * vc[p] - gravity * gc
            speed = math.hypot(vr[p], vc[p])
            if speed < min_speed:
                slow[p] += 1
                if slow[p] >= static_steps:
                    active[p] = False
                continue
            slow[p] = 0
            f = min(1.0, 1.0 / speed)
            qr = pr[p] + f * vr[p]
            qc = pc[p] + f * vc[p]
            ri, ci = int(math.floor(qr)), int(math.floor(qc))
            if ri < 0 or ri >= ny or ci < 0 or ci >= nx:
                fate[p] = RIVER_EXIT
                active[p] = False
                continue
            pr[p], pc[p] = qr, qc
            o = owner[ri, ci]
            if o == p:
                continue
            k = path_n[p]
            if k >= path_r.shape[1]:
                active[p] = False
                continue
            path_r[p, k] = ri
            path_c[p, k] = ci
            path_n[p] = k + 1
            if o >= 0:
                fate[p] = RIVER_JOINED
                joins[p] = o
                active[p] = False
                mass[o] += mass[p]
                if active[o]:
                    vr[o] += vr[p]
                    vc[o] += vc[p]
                continue
            owner[ri, ci] = p
        if not any_active:
            break
    return fate
