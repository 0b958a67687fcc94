"""Numerical kernels of the terrain renderer (ndarrays and scalars only).

numba is used where numpy cannot vectorise: dart throwing with a background grid
(each acceptance depends on the previous ones), per-triangle scan conversion
(variable-size pixel loops) and sweeps along an oriented river forest (each node
depends on its donors).
"""
from __future__ import annotations

import heapq
import math

import numpy as np
from numba import get_num_threads, njit, prange

from orokit.topology._kernels import ascent_pointer


@njit(cache=True, nogil=True)
def poisson_disk(xmin: float, ymin: float, xmax: float, ymax: float, radius: float,
                 n_trials: int, seed: int) -> np.ndarray:
    """Dart-throwing blue noise: points of the box at mutual distance >= ``radius``.

    A background grid of cell ``radius / sqrt(2)`` holds at most one point per cell, so
    each dart checks a 5 x 5 neighbourhood. ``n_trials`` uniform darts are thrown
    (numba: sequential acceptance cannot be vectorised). Releases the GIL (numba's random
    state is per thread and seeded here, so any thread gives the same points).
    """
    np.random.seed(seed)
    cell = radius / np.sqrt(2.0)
    nx = int(np.ceil((xmax - xmin) / cell)) + 1
    ny = int(np.ceil((ymax - ymin) / cell)) + 1
    grid = -np.ones((ny, nx), np.int64)
    out = np.empty((nx * ny, 2))
    n = 0
    r2 = radius * radius
    for _ in range(n_trials):
        x = xmin + np.random.random() * (xmax - xmin)
        y = ymin + np.random.random() * (ymax - ymin)
        gi = int((y - ymin) / cell)
        gj = int((x - xmin) / cell)
        if grid[gi, gj] >= 0:
            continue
        ok = True
        for di in range(-2, 3):
            ii = gi + di
            if ii < 0 or ii >= ny:
                continue
            for dj in range(-2, 3):
                jj = gj + dj
                if jj < 0 or jj >= nx:
                    continue
                k = grid[ii, jj]
                if k >= 0:
                    dx = out[k, 0] - x
                    dy = out[k, 1] - y
                    if dx * dx + dy * dy < r2:
                        ok = False
                        break
            if not ok:
                break
        if ok:
            grid[gi, gj] = n
            out[n, 0] = x
            out[n, 1] = y
            n += 1
    return out[:n].copy()


@njit(cache=True, nogil=True)
def flood_from_outlets(start: np.ndarray, dst: np.ndarray, elen: np.ndarray, bnd: np.ndarray, outlets: np.ndarray,
                       base_elevation: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Priority flood of a graph (CSR ``start`` / ``dst``, edge lengths ``elen``) from the ``outlets``,
    lowest ``(max bound on the way, flow distance, node)`` first: receivers, flow distances and the
    nodes in the order reached. Every heap entry is a distinct node, so the entries pop in one total
    order, the order of Python's ``heapq`` on the same tuples (numba: a loop over ~10^5 nodes)."""
    n = bnd.size
    receiver = np.full(n, -1, np.int64)
    fd = np.zeros(n)
    seen = np.zeros(n, np.bool_)
    order = np.empty(n, np.int64)
    heap = [(0.0, 0.0, np.int64(0))]
    heap.pop()
    for t in range(outlets.size):
        o = outlets[t]
        b = bnd[o]
        heapq.heappush(heap, (base_elevation if base_elevation < b else b, 0.0, o))
        seen[o] = True
    no = 0
    while len(heap) > 0:
        key, dist, v = heapq.heappop(heap)
        order[no] = v
        no += 1
        for k in range(start[v], start[v + 1]):
            w = dst[k]
            if seen[w]:
                continue
            seen[w] = True
            receiver[w] = v
            fd[w] = dist + elen[k]
            b = bnd[w]
            heapq.heappush(heap, (b if b > key else key, dist + elen[k], w))
    return receiver, fd, order[:no].copy()


@njit(cache=True, nogil=True, parallel=True)
def rasterize_triangles(vx: np.ndarray, vy: np.ndarray, vz: np.ndarray, tri: np.ndarray,
                        x0: float, y0: float, res: float, ny: int, nx: int) -> np.ndarray:
    """Barycentric scan conversion of a TIN onto cell centres.

    Cell ``(i, j)`` has centre ``(x0 + (j + 0.5) res, y0 - (i + 0.5) res)`` (``y0`` is
    the top edge). Cells not covered by any triangle stay NaN; a cell on a shared edge takes
    the value of the last triangle that covers it (numba: per-triangle loops over a variable
    number of cells; bands of rows on all threads, each taking the triangles in order, so
    every cell gets the value of one pass over the triangles).
    """
    out = np.full((ny, nx), np.nan, np.float32)
    tol = -1e-9
    nt = tri.shape[0]
    box = np.empty((nt, 4), np.int64)  # imin, imax, jmin, jmax (imin > imax: no cell)
    for t in prange(nt):
        a, b, c = tri[t, 0], tri[t, 1], tri[t, 2]
        ax, ay = vx[a], vy[a]
        bx, by = vx[b], vy[b]
        cx, cy = vx[c], vy[c]
        det = (by - cy) * (ax - cx) + (cx - bx) * (ay - cy)
        if det == 0.0:
            box[t, 0] = 1
            box[t, 1] = 0
            continue
        box[t, 2] = max(int(np.floor((min(ax, bx, cx) - x0) / res - 0.5)), 0)
        box[t, 3] = min(int(np.ceil((max(ax, bx, cx) - x0) / res - 0.5)), nx - 1)
        box[t, 0] = max(int(np.floor((y0 - max(ay, by, cy)) / res - 0.5)), 0)
        box[t, 1] = min(int(np.ceil((y0 - min(ay, by, cy)) / res - 0.5)), ny - 1)
    nb = min(ny, 8)  # each band looks at every triangle's box: few bands
    for bnd in prange(nb):
        r0 = bnd * ny // nb
        r1 = (bnd + 1) * ny // nb - 1
        for t in range(nt):
            imin = max(box[t, 0], r0)
            imax = min(box[t, 1], r1)
            if imin > imax:
                continue
            a, b, c = tri[t, 0], tri[t, 1], tri[t, 2]
            ax, ay, az = vx[a], vy[a], vz[a]
            bx, by, bz = vx[b], vy[b], vz[b]
            cx, cy, cz = vx[c], vy[c], vz[c]
            det = (by - cy) * (ax - cx) + (cx - bx) * (ay - cy)
            jmin = box[t, 2]
            jmax = box[t, 3]
            for i in range(imin, imax + 1):
                py = y0 - (i + 0.5) * res
                for j in range(jmin, jmax + 1):
                    px = x0 + (j + 0.5) * res
                    l1 = ((by - cy) * (px - cx) + (cx - bx) * (py - cy)) / det
                    l2 = ((cy - ay) * (px - cx) + (ax - cx) * (py - cy)) / det
                    l3 = 1.0 - l1 - l2
                    if l1 >= tol and l2 >= tol and l3 >= tol:
                        out[i, j] = l1 * az + l2 * bz + l3 * cz
    return out


@njit(cache=True)
def river_elevations(order: np.ndarray, receiver: np.ndarray, length: np.ndarray,
                     h: np.ndarray, slope: float, floor: float) -> np.ndarray:
    """Downstream pass: ``h[r] = min(h[r], h[d] - slope * length[d])`` over donors ``d``.

    ``order`` lists nodes from outlets upstream (flood order); it is walked backwards so
    every donor is final before its receiver. Nodes never go below ``floor``
    (numba: sequential dependency along the forest).
    """
    out = h.copy()
    for k in range(order.size - 1, -1, -1):
        v = order[k]
        if out[v] < floor:
            out[v] = floor
        r = receiver[v]
        if r >= 0:
            cand = out[v] - slope * length[v]
            if cand < out[r]:
                out[r] = cand
    return out


@njit(cache=True)
def river_rise_bound(order: np.ndarray, receiver: np.ndarray, rise: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Upstream pass: ``h[d] = min(h[d], h[r] + rise[d])`` from the outlets up (``order`` lists
    receivers before donors), so no bed stands more than ``rise`` above its receiver's final bed
    (numba: sequential dependency along the forest)."""
    out = h.copy()
    for k in range(order.size):
        v = order[k]
        r = receiver[v]
        if r >= 0:
            cap = out[r] + rise[v]
            if out[v] > cap:
                out[v] = cap
    return out


@njit(cache=True)
def chi_and_basin(receiver: np.ndarray, step: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """From the outlets upstream (nodes numbered receivers before donors): ``chi[v] = chi[receiver] +
    step[v]`` (0 at an outlet) and the outlet each node drains to (numba: sequential along the forest)."""
    n = receiver.size
    chi = np.zeros(n)
    basin = np.arange(n)
    for v in range(n):
        r = receiver[v]
        if r >= 0:
            chi[v] = chi[r] + step[v]
            basin[v] = basin[r]
    return chi, basin


@njit(cache=True)
def accumulate(order: np.ndarray, receiver: np.ndarray, local: np.ndarray) -> np.ndarray:
    """Drainage accumulation along the forest (``order`` from outlets upstream)."""
    out = local.copy()
    for k in range(order.size - 1, -1, -1):
        v = order[k]
        r = receiver[v]
        if r >= 0:
            out[r] += out[v]
    return out


@njit(cache=True)
def reconstruct_from_markers(indptr: np.ndarray, indices: np.ndarray, h: np.ndarray,
                             marker: np.ndarray) -> np.ndarray:
    """Grey reconstruction by dilation on a graph: ``min(h, best bottleneck from a marker)``.

    Every vertex not reachable from a marker through ground at least as high keeps
    only the height of its highest path from a marker, so the only local maxima left
    are the markers (spurious hills become flat shelves at their pass height). A
    max-heap sweep from the markers (numba: priority queue).
    """
    n = h.size
    out = np.full(n, -np.inf)
    done = np.zeros(n, np.bool_)
    heap = [(0.0, np.int64(0))]
    heap.pop()
    for u in range(n):
        if marker[u]:
            out[u] = h[u]
            heapq.heappush(heap, (-h[u], np.int64(u)))
    while heap:
        negz, v = heapq.heappop(heap)
        if done[v]:
            continue
        done[v] = True
        zv = -negz
        for k in range(indptr[v], indptr[v + 1]):
            w = indices[k]
            if done[w]:
                continue
            cand = min(zv, h[w])
            if cand > out[w]:
                out[w] = cand
                heapq.heappush(heap, (-cand, w))
    for u in range(n):
        if not done[u]:
            out[u] = h[u]
    return out


@njit(cache=True)
def carve_saddles(z: np.ndarray, x0: float, y0: float, res: float, sx: np.ndarray, sy: np.ndarray,
                  sz: np.ndarray, nxv: np.ndarray, nyv: np.ndarray, max_len: float, drop: float,
                  label: np.ndarray, slope: float = 0.0, max_depth: float = 0.0) -> int:
    """Cut a 4-connected trench through each saddle, perpendicular to its ridge (in place).

    From the saddle, both ways along the unit normal ``(nxv, nyv)``, cells are lowered
    to ``min(z, sz - drop)`` until the ground is already below ``sz - drop`` (or after
    ``max_len`` metres) or a cell of another ridge (``label`` holds the ridge id of
    each burnt cell; saddle ``s`` belongs to ridge ``s``), so no path beside the saddle
    crosses the ridge above it. With ``slope`` > 0 the trench descends from the saddle:
    a cell at distance ``t`` goes to ``min(z, sz - drop - min(slope t, max_depth))`` (a col
    falling away on both sides, not a level groove); where it stops is the same. Each
    diagonal step also lowers one 4-neighbour so the trench stops 8-connected paths.
    Returns the number of cells lowered (numba: walks of data-dependent length).
    """
    ny, nx = z.shape
    count = 0
    for s in range(sx.size):
        target = np.float32(sz[s] - drop)
        for side in (-1.0, 1.0):
            pi = -1
            pj = -1
            t = 0.5 * res
            while t <= max_len:
                x = sx[s] + side * nxv[s] * t
                y = sy[s] + side * nyv[s] * t
                j = int(np.floor((x - x0) / res))
                i = int(np.floor((y0 - y) / res))
                here = np.float32(target - min(slope * t, max_depth))
                t += 0.5 * res
                if i < 0 or i >= ny or j < 0 or j >= nx:
                    break
                if i == pi and j == pj:
                    continue
                if label[i, j] >= 0 and label[i, j] != s:
                    break
                if pi >= 0 and i != pi and j != pj:
                    if z[pi, j] > here:
                        z[pi, j] = here
                        count += 1
                pi, pj = i, j
                if z[i, j] <= target:
                    if t > 1.5 * res:
                        break
                    if z[i, j] <= here:
                        continue
                if z[i, j] > here:
                    z[i, j] = here
                    count += 1
    return count


@njit(cache=True, nogil=True)
def _grow(a: np.ndarray, n: int) -> np.ndarray:
    if n < a.size:
        return a
    b = np.empty(2 * a.size, a.dtype)
    b[:a.size] = a
    return b


@njit(cache=True, nogil=True)
def _heap_push(hk: np.ndarray, hv: np.ndarray, n: int, key: np.float32, val: np.int64
               ) -> tuple[np.ndarray, np.ndarray, int]:
    """Push ``(key, val)`` on the binary max-heap ``hk[:n], hv[:n]`` (grown by doubling when full);
    returns the arrays and the new size. The top is the highest key, then the lowest value: the
    order ``heapq`` gives ``(-key, val)``, so distinct entries pop in the same sequence."""
    if n == hk.size:
        k2 = np.empty(2 * n, hk.dtype)
        v2 = np.empty(2 * n, hv.dtype)
        k2[:n] = hk
        v2[:n] = hv
        hk, hv = k2, v2
    i = n
    while i > 0:
        p = (i - 1) >> 1
        if not (key > hk[p] or (key == hk[p] and val < hv[p])):
            break
        hk[i] = hk[p]
        hv[i] = hv[p]
        i = p
    hk[i] = key
    hv[i] = val
    return hk, hv, n + 1


@njit(cache=True, nogil=True)
def _heap_pop(hk: np.ndarray, hv: np.ndarray, n: int) -> int:
    """Remove the top ``hk[0], hv[0]`` of the heap of size ``n`` (read it first); returns the new size."""
    n -= 1
    key = hk[n]
    val = hv[n]
    i = 0
    while True:
        c = 2 * i + 1
        if c >= n:
            break
        if c + 1 < n and (hk[c + 1] > hk[c] or (hk[c + 1] == hk[c] and hv[c + 1] < hv[c])):
            c += 1
        if not (hk[c] > key or (hk[c] == key and hv[c] < val)):
            break
        hk[i] = hk[c]
        hv[i] = hv[c]
        i = c
    hk[i] = key
    hv[i] = val
    return n


@njit(cache=True, nogil=True)
def mask_components(mask: np.ndarray, z: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """8-connected components of ``mask`` and the finite cells of ``z`` beside each: ``comp`` (int32 per
    cell, -1 outside the mask), the flat cells of each component (``cells[offsets[k]:offsets[k + 1]]``,
    components in raster order of their first cell), ``offsets``, and the unmasked cells 8-adjacent to
    component ``k`` where ``z`` is finite, each once (``seeds[seed_offsets[k]:seed_offsets[k + 1]]``, in
    the order the search meets them) and ``seed_offsets`` (numba: one breadth-first search, which visits
    every neighbour of every masked cell anyway; a seed is marked ``-2 - k`` in ``comp`` while component
    ``k`` is searched)."""
    ny, nx = mask.shape
    comp = np.full((ny, nx), -1, np.int32)
    cells = np.empty(max(int(mask.sum()), 1), np.int64)
    seeds = np.empty(1024, np.int64)
    offsets = [0]
    seed_offsets = [0]
    n = 0
    ns = 0
    k = 0
    for i0 in range(ny):
        for j0 in range(nx):
            if not mask[i0, j0] or comp[i0, j0] >= 0:
                continue
            comp[i0, j0] = k
            head = n
            cells[n] = i0 * nx + j0
            n += 1
            mark = -2 - k
            while head < n:
                v = cells[head]
                head += 1
                i = v // nx
                j = v - i * nx
                for ii in range(max(i - 1, 0), min(i + 2, ny)):
                    for jj in range(max(j - 1, 0), min(j + 2, nx)):
                        if mask[ii, jj]:
                            if comp[ii, jj] < 0:
                                comp[ii, jj] = k
                                cells[n] = ii * nx + jj
                                n += 1
                        elif comp[ii, jj] != mark and np.isfinite(z[ii, jj]):
                            comp[ii, jj] = mark
                            seeds = _grow(seeds, ns)
                            seeds[ns] = ii * nx + jj
                            ns += 1
            k += 1
            offsets.append(n)
            seed_offsets.append(ns)
    for t in range(ns):
        s = seeds[t]
        i = s // nx
        comp[i, s - i * nx] = -1
    return comp, cells[:n], np.array(offsets, np.int64), seeds[:ns], np.array(seed_offsets, np.int64)


@njit(cache=True, nogil=True)
def _flood_component(z: np.ndarray, comp: np.ndarray, best: np.ndarray, base: np.ndarray, seeds: np.ndarray,
                     k: int, step: float, grade: float, max_depth: float) -> int:
    """:func:`reconstruct_masked` on the component ``k`` of the mask: only its cells and the unmasked
    cells beside them (``seeds``, each once) take part, so components flood independently. The heap
    pops its entries (distinct ``(height, cell)`` pairs) in one order whatever order they were pushed
    in."""
    ny, nx = z.shape
    graded = grade > 0.0
    hk = np.empty(max(16, seeds.size), np.float32)
    hv = np.empty(max(16, seeds.size), np.int64)
    nh = 0
    for t in range(seeds.size):
        s = seeds[t]
        i = s // nx
        hk, hv, nh = _heap_push(hk, hv, nh, z[i, s - i * nx], s)
    inf = np.float32(np.inf)
    count = 0
    while nh > 0:
        zv = hk[0]
        v = hv[0]
        nh = _heap_pop(hk, hv, nh)
        i = v // nx
        j = v - i * nx
        bv = zv  # an unmasked cell is its own pass
        if comp[i, j] == k:
            if best[i, j] == inf:  # popped before at a higher offer: final
                continue
            if best[i, j] < z[i, j]:
                z[i, j] = best[i, j]
                count += 1
            best[i, j] = inf
            if graded:
                bv = base[i, j]
        down = np.float32(step)
        if graded and zv - grade >= bv - max_depth:
            down = np.float32(grade)
        for ii in range(max(i - 1, 0), min(i + 2, ny)):
            for jj in range(max(j - 1, 0), min(j + 2, nx)):
                if comp[ii, jj] != k:
                    continue
                b = best[ii, jj]
                if b == inf:
                    continue
                h = z[ii, jj]
                if not np.isfinite(h):
                    continue
                if h < zv:
                    cand = h
                    cb = h
                else:
                    cand = zv - down
                    cb = bv
                if cand > b:
                    best[ii, jj] = cand
                    if graded:
                        base[ii, jj] = cb
                    hk, hv, nh = _heap_push(hk, hv, nh, cand, ii * nx + jj)
    return count


@njit(cache=True, nogil=True)
def _component_lanes(offsets: np.ndarray, seed_offsets: np.ndarray, n_lanes: int) -> tuple[np.ndarray, np.ndarray]:
    """The mask components shared among ``n_lanes`` threads: largest first (cells + seeds), each to the lane
    with the least work so far (``lane_items[lane_offsets[l]:lane_offsets[l + 1]]``); a static split of
    the raster-ordered components gave one thread 58 % of the 90 km render's first cut."""
    nc = offsets.size - 1
    size = (offsets[1:] - offsets[:-1]) + (seed_offsets[1:] - seed_offsets[:-1])
    order = np.argsort(-size, kind="mergesort")
    load = np.zeros(n_lanes, np.int64)
    lane = np.empty(nc, np.int64)
    for t in range(nc):
        k = order[t]
        best = 0
        for m in range(1, n_lanes):
            if load[m] < load[best]:
                best = m
        lane[k] = best
        load[best] += size[k]
    lane_offsets = np.zeros(n_lanes + 1, np.int64)
    for k in range(nc):
        lane_offsets[lane[k] + 1] += 1
    for m in range(n_lanes):
        lane_offsets[m + 1] += lane_offsets[m]
    fill = lane_offsets[:-1].copy()
    lane_items = np.empty(nc, np.int64)
    for t in range(nc):
        k = order[t]
        lane_items[fill[lane[k]]] = k
        fill[lane[k]] += 1
    return lane_items, lane_offsets


def reconstruct_masked(z: np.ndarray, mask: np.ndarray, step: float, grade: float = 0.0,
                       max_depth: float = 0.0) -> int:
    """Lower the hills inside ``mask`` that hold no marker (peak cutting, in place).

    Cells outside ``mask`` keep their elevation and seed the flood at their height; a
    masked cell becomes ``min(z, b - step * k)`` with ``b`` the bottleneck height of its
    best path from an unmasked cell, so masked hills are cut down to their pass and get a
    strictly ascending path out. With ``grade`` > 0 the cut falls ``grade`` per cell (a
    shallow bowl below the pass instead of a flat shelf) until it is ``max_depth`` below
    the pass it hangs from, then ``step`` per cell again. Used with ``mask`` = basins of
    spurious maxima, whose outside already ascends to a marker. Returns the number of
    lowered cells (numba: a priority queue per 8-connected component of the mask
    (:func:`mask_components`), the components on all threads, largest first
    (:func:`_component_lanes`); a component's cells take offers only from each other and the unmasked
    cells beside them, so this is the one flood of the whole mask, whichever thread floods a component).
    """
    return int(_reconstruct_lanes(z, mask, step, grade, max_depth, get_num_threads()))


@njit(cache=True, nogil=True, parallel=True)
def _reconstruct_lanes(z: np.ndarray, mask: np.ndarray, step: float, grade: float, max_depth: float,
                       n_lanes: int) -> int:
    """:func:`reconstruct_masked` with the components shared among ``n_lanes`` threads."""
    ny, nx = z.shape
    comp, _, offsets, seeds, seed_offsets = mask_components(mask, z)
    best = np.full((ny, nx), -np.inf, np.float32)  # the best offer so far; +inf once final
    base = np.zeros((ny, nx) if grade > 0.0 else (1, 1), np.float32)  # the pass a cut cell hangs from
    lane_items, lane_offsets = _component_lanes(offsets, seed_offsets, n_lanes)
    counts = np.zeros(n_lanes, np.int64)
    for m in prange(n_lanes):
        c = 0
        for t in range(lane_offsets[m], lane_offsets[m + 1]):
            k = lane_items[t]
            c += _flood_component(z, comp, best, base, seeds[seed_offsets[k]:seed_offsets[k + 1]], k, step, grade,
                                  max_depth)
        counts[m] = c
    return counts.sum()


@njit(cache=True)
def merge_tree(n: int, ea: np.ndarray, eb: np.ndarray, ez: np.ndarray):
    """Kruskal merge tree of a Divide Tree: ``parent``, ``height`` and ``depth`` of its
    ``2n - 1`` nodes (leaves 0..n-1 are the peaks; an inner node is the saddle where two
    components join). The bottleneck between two peaks is the height of their lowest
    common ancestor (numba: union-find)."""
    m = ea.size
    parent = np.full(n + m, -1, np.int64)
    height = np.full(n + m, np.inf)
    comp = np.arange(n)  # union-find over peaks
    top = np.arange(n)  # merge-tree node of each component root
    order = np.argsort(-ez, kind="mergesort")
    nxt = n
    for k in order:
        a = ea[k]
        while comp[a] != a:
            comp[a] = comp[comp[a]]
            a = comp[a]
        b = eb[k]
        while comp[b] != b:
            comp[b] = comp[comp[b]]
            b = comp[b]
        if a == b:
            continue
        parent[top[a]] = nxt
        parent[top[b]] = nxt
        height[nxt] = ez[k]
        comp[b] = a
        top[a] = nxt
        nxt += 1
    depth = np.zeros(n + m, np.int64)
    for v in range(nxt - 1, -1, -1):  # parents have larger ids
        if parent[v] >= 0:
            depth[v] = depth[parent[v]] + 1
    return parent[:nxt], height[:nxt], depth[:nxt]


@njit(cache=True)
def bottlenecks(parent: np.ndarray, height: np.ndarray, depth: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Bottleneck (lowest saddle on the tree path) of peak pairs ``(a, b)``; -inf when the
    peaks are in different trees (numba: lowest-common-ancestor walks)."""
    out = np.empty(a.size)
    for k in range(a.size):
        u = a[k]
        v = b[k]
        while depth[u] > depth[v]:
            u = parent[u]
        while depth[v] > depth[u]:
            v = parent[v]
        while u != v and u >= 0 and v >= 0:
            u = parent[u]
            v = parent[v]
        out[k] = height[u] if (u == v and u >= 0) else -np.inf
    return out


@njit(cache=True)
def flood_levels(z: np.ndarray, mask: np.ndarray, owner: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pass level and flood source of every cell in ``mask`` (nothing is modified).

    ``level`` is the height of the best path from an unmasked cell (the highest bottleneck:
    grey reconstruction by dilation), ``source`` the ``owner`` of the unmasked cell that
    path starts from; both stay ``-inf`` / -1 outside ``mask`` and where no path exists
    (numba: priority queue).
    """
    ny, nx = z.shape
    heap = [(np.float32(0.0), np.int64(0))]
    heap.pop()
    level = np.full((ny, nx), -np.inf, np.float32)
    source = np.full((ny, nx), -1, np.int64)
    done = ~mask
    for i in range(ny):
        for j in range(nx):
            if not mask[i, j]:
                continue
            for di in range(-1, 2):
                ii = i + di
                if ii < 0 or ii >= ny:
                    continue
                for dj in range(-1, 2):
                    jj = j + dj
                    if jj < 0 or jj >= nx or mask[ii, jj] or owner[ii, jj] < 0:
                        continue
                    h = z[ii, jj]
                    if np.isfinite(h) and h > level[ii, jj]:
                        level[ii, jj] = h
                        source[ii, jj] = owner[ii, jj]
                        heapq.heappush(heap, (-h, np.int64(ii * nx + jj)))
    while heap:
        negz, v = heapq.heappop(heap)
        i = v // nx
        j = v - i * nx
        if mask[i, j]:
            if done[i, j]:
                continue
            done[i, j] = True
        zv = -negz
        if zv < level[i, j]:
            continue
        for di in range(-1, 2):
            ii = i + di
            if ii < 0 or ii >= ny:
                continue
            for dj in range(-1, 2):
                jj = j + dj
                if jj < 0 or jj >= nx or done[ii, jj]:
                    continue
                h = z[ii, jj]
                if not np.isfinite(h):
                    continue
                cand = h if h < zv else zv
                if cand > level[ii, jj]:
                    level[ii, jj] = cand
                    source[ii, jj] = source[i, j]
                    heapq.heappush(heap, (-cand, np.int64(ii * nx + jj)))
    for i in range(ny):
        for j in range(nx):
            if not mask[i, j]:
                level[i, j] = -np.inf
                source[i, j] = -1
    return level, source


@njit(cache=True, nogil=True, parallel=True)
def basin_owner(lab: np.ndarray, tid: np.ndarray) -> np.ndarray:
    """``tid[lab]`` where ``lab >= 0``, else -2 (NaN cells): the tree peak owning each cell's
    basin (one pass on all threads; same values as ``np.where(lab >= 0, tid[max(lab, 0)], -2)``)."""
    out = np.empty(lab.size, np.int64)
    for i in prange(lab.size):
        v = lab[i]
        out[i] = tid[v] if v >= 0 else -2
    return out


@njit(cache=True, nogil=True)
def border_pairs(owner: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Flat indices ``(a, b)`` of 8-adjacent cells whose ``owner`` differs (both >= 0): for the
    offsets E, SW, S, SE in turn, the pairs in raster order of ``a``."""
    ny, nx = owner.shape
    cnt = 0
    for step in range(2):
        if step == 1:
            ia = np.empty(cnt, np.int64)
            ib = np.empty(cnt, np.int64)
            cnt = 0
        for d in range(4):
            dr = 0 if d == 0 else 1
            dc = 1 if d == 0 else d - 2  # E, then SW, S, SE
            for i in range(ny - dr):
                for j in range(max(0, -dc), nx - max(0, dc)):
                    oa = owner[i, j]
                    ob = owner[i + dr, j + dc]
                    if oa != ob and oa >= 0 and ob >= 0:
                        if step == 1:
                            ia[cnt] = i * nx + j
                            ib[cnt] = (i + dr) * nx + j + dc
                        cnt += 1
    return ia, ib


@njit(cache=True, nogil=True)
def update_basins(z: np.ndarray, ptr: np.ndarray, lab: np.ndarray, own: np.ndarray, tid: np.ndarray,
                  changed: np.ndarray, peak_cells: np.ndarray, peak_ids: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Basins of steepest ascent after the cells ``changed`` (flat) of ``z`` changed (in place).

    ``ptr`` (every cell's :func:`~orokit.topology._kernels.ascent_pointer`), ``lab`` (basin id per
    cell) and ``own`` (``tid`` of the basin: the tree peak owning it, -1 for a spurious maximum, -2
    for NaN cells) held for the raster before the change. Only the pointers of the changed cells and
    their neighbours can change; only the cells whose ascent chain passes through a changed pointer (found backwards
    from those cells) can change basin; they are relabelled by following their new chains. A new
    maximum gets the next basin id (``tid.size``, ...) and the tree peak of its cell
    (``peak_cells`` sorted, ``peak_ids`` beside them; -1 if none). Returns the new maxima's cells
    and their ``tid`` (append them to the basin arrays), and the relabelled cells (no other cell's
    owner changed). Each cell's owner is that of a full relabelling; basin ids differ from it (old
    ids of vanished maxima are left unused).
    """
    H, W = z.shape
    mark = np.zeros(H * W, np.uint8)  # 1: pointer recomputed, 2: may change basin
    queue = np.empty(max(16, 4 * changed.size), np.int64)
    nq = 0
    for t in range(changed.size):
        c0 = changed[t]
        r0 = c0 // W
        k0 = c0 - r0 * W
        for r in range(max(r0 - 1, 0), min(r0 + 2, H)):
            for c in range(max(k0 - 1, 0), min(k0 + 2, W)):
                j = r * W + c
                if mark[j] != 0:
                    continue
                mark[j] = 1
                p = ascent_pointer(z, r, c)
                if p != ptr[j]:
                    ptr[j] = p
                    mark[j] = 2
                    queue = _grow(queue, nq)
                    queue[nq] = j
                    nq += 1
    head = 0
    while head < nq:  # every cell whose chain enters a changed pointer
        x = queue[head]
        head += 1
        r0 = x // W
        k0 = x - r0 * W
        for r in range(max(r0 - 1, 0), min(r0 + 2, H)):
            for c in range(max(k0 - 1, 0), min(k0 + 2, W)):
                j = r * W + c
                if mark[j] != 2 and ptr[j] == x:
                    mark[j] = 2
                    queue = _grow(queue, nq)
                    queue[nq] = j
                    nq += 1
    for t in range(nq):
        lab[queue[t]] = -3  # unresolved
    new_top, new_tid = _resolve_basins(ptr, lab, own, tid, queue[:nq], peak_cells, peak_ids)
    return new_top, new_tid, queue[:nq].copy()


@njit(cache=True, nogil=True, parallel=True)
def feature_distance(ft: np.ndarray, sampling: float) -> np.ndarray:
    """float32 distance of every cell to the feature cell ``ft[:, i, j]`` (``return_indices`` of
    :func:`scipy.ndimage.distance_transform_edt`): the same float64 operations as scipy's own
    distances (``sqrt((di s)^2 + (dj s)^2)``), then rounded to float32, without its four float64
    rasters (rows on all threads)."""
    _, ny, nx = ft.shape
    out = np.empty((ny, nx), np.float32)
    for i in prange(ny):
        for j in range(nx):
            di = np.float64(ft[0, i, j] - i) * sampling
            dj = np.float64(ft[1, i, j] - j) * sampling
            out[i, j] = np.float32(np.sqrt(di * di + dj * dj))
    return out


_HASH_MUL = np.int64(-7046029254386353131)  # 0x9E3779B97F4A7C15 (Fibonacci hashing), wrapping int64


@njit(cache=True, nogil=True)
def _bottleneck(parent: np.ndarray, height: np.ndarray, depth: np.ndarray, u: int, v: int) -> float:
    """:func:`bottlenecks` of one pair."""
    while depth[u] > depth[v]:
        u = parent[u]
    while depth[v] > depth[u]:
        v = parent[v]
    while u != v and u >= 0 and v >= 0:
        u = parent[u]
        v = parent[v]
    return height[u] if (u == v and u >= 0) else -np.inf


@njit(cache=True, nogil=True)
def pass_violations(owner: np.ndarray, z: np.ndarray, parent: np.ndarray, height: np.ndarray, depth: np.ndarray,
                    n: int, tol: float, d0: int = 0, d1: int = 4) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """The pairs of :func:`border_pairs` (same order) whose lower cell is more than ``tol`` above the
    finite bottleneck (:func:`bottlenecks`) between their two owners: flat indices ``(a, b)``, the
    bottleneck of each, and the number of pairs looked at. One pass; each owner pair's bottleneck is
    computed once (a hash table on ``lo * n + hi``). ``d0, d1``: only the neighbour directions
    ``d0 <= d < d1`` (E, SW, S, SE), so two calls on directions ``[0, k)`` and ``[k, 4)`` give the
    whole answer in two concatenated parts (both releasing the GIL)."""
    ny, nx = owner.shape
    size = 1 << 12
    keys = np.full(size, -1, np.int64)
    vals = np.empty(size, np.float64)
    used = 0
    ia = np.empty(64, np.int64)
    ib = np.empty(64, np.int64)
    bv = np.empty(64, np.float64)
    nv = 0
    total = 0
    for d in range(d0, d1):
        dr = 0 if d == 0 else 1
        dc = 1 if d == 0 else d - 2  # E, then SW, S, SE
        for i in range(ny - dr):
            for j in range(max(0, -dc), nx - max(0, dc)):
                oa = owner[i, j]
                ob = owner[i + dr, j + dc]
                if oa == ob or oa < 0 or ob < 0:
                    continue
                total += 1
                lo = min(oa, ob)
                hi = max(oa, ob)
                key = lo * n + hi
                if 2 * (used + 1) > size:  # grow the table (load <= 1/2)
                    size *= 2
                    k2 = np.full(size, -1, np.int64)
                    v2 = np.empty(size, np.float64)
                    for t in range(keys.size):
                        if keys[t] >= 0:
                            s = (keys[t] * _HASH_MUL) & (size - 1)
                            while k2[s] >= 0:
                                s = (s + 1) & (size - 1)
                            k2[s] = keys[t]
                            v2[s] = vals[t]
                    keys, vals = k2, v2
                s = (key * _HASH_MUL) & (size - 1)
                while keys[s] >= 0 and keys[s] != key:
                    s = (s + 1) & (size - 1)
                if keys[s] < 0:
                    keys[s] = key
                    vals[s] = _bottleneck(parent, height, depth, lo, hi)
                    used += 1
                bn = vals[s]
                za = np.float64(z[i, j])
                zb = np.float64(z[i + dr, j + dc])
                if min(za, zb) > bn + tol and np.isfinite(bn):
                    if nv == ia.size:
                        ia = _grow(ia, nv)
                        ib = _grow(ib, nv)
                        bv = _grow(bv, nv)
                    ia[nv] = i * nx + j
                    ib[nv] = (i + dr) * nx + j + dc
                    bv[nv] = bn
                    nv += 1
    return ia[:nv].copy(), ib[:nv].copy(), bv[:nv].copy(), total


@njit(cache=True, nogil=True)
def _pass_check(owner: np.ndarray, z: np.ndarray, parent: np.ndarray, height: np.ndarray, depth: np.ndarray,
                tol: float, a: int, b: int) -> float:
    """The bottleneck of the pair of flat cells ``(a, b)`` if it is a violation of :func:`pass_violations`
    (owners differ, both >= 0, lower cell above the finite bottleneck + ``tol``), else NaN."""
    oa = owner[a]
    ob = owner[b]
    if oa == ob or oa < 0 or ob < 0:
        return np.nan
    bn = _bottleneck(parent, height, depth, min(oa, ob), max(oa, ob))
    if min(np.float64(z[a]), np.float64(z[b])) > bn + tol and np.isfinite(bn):
        return bn
    return np.nan


@njit(cache=True, nogil=True)
def pass_violations_near(owner: np.ndarray, z: np.ndarray, parent: np.ndarray, height: np.ndarray,
                         depth: np.ndarray, tol: float, cells: np.ndarray, ia: np.ndarray, ib: np.ndarray,
                         bn: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`pass_violations` (all directions) when only the ``cells`` (flat, repeats allowed) changed owner
    or elevation since the call that returned ``(ia, ib, bn)``: its pairs without a changed cell are
    kept (a pair's verdict depends on its two cells only), the pairs at a changed cell are checked
    again; the same arrays, in the same order (direction E, SW, S, SE, then raster order of ``a``)."""
    ny, nx = owner.shape
    size = ny * nx
    own = owner.reshape(-1)
    zf = z.reshape(-1)
    mark = np.zeros(size, np.uint8)
    for t in range(cells.size):
        mark[cells[t]] = 1
    keys = np.empty(64, np.int64)  # direction * size + a
    vals = np.empty(64, np.float64)
    nk = 0
    for t in range(ia.size):
        a = ia[t]
        b = ib[t]
        if mark[a] != 0 or mark[b] != 0:
            continue
        ra = a // nx
        rb = b // nx
        d = 0 if rb == ra else (b - rb * nx) - (a - ra * nx) + 2  # E, or SW / S / SE by column step
        keys = _grow(keys, nk)
        vals = _grow(vals, nk)
        keys[nk] = d * size + a
        vals[nk] = bn[t]
        nk += 1
    for t in range(cells.size):
        c = cells[t]
        if mark[c] != 1:
            continue
        mark[c] = 2
        i = c // nx
        j = c - i * nx
        for d in range(4):
            dr = 0 if d == 0 else 1
            dc = 1 if d == 0 else d - 2
            for side in range(2):  # c as the pair's first cell, then as its second
                ai = i if side == 0 else i - dr
                aj = j if side == 0 else j - dc
                bi = ai + dr
                bj = aj + dc
                if ai < 0 or bi >= ny or min(aj, bj) < 0 or max(aj, bj) >= nx:
                    continue
                a = ai * nx + aj
                if side == 1 and mark[a] != 0:  # a changed cell: checked as its own first cell
                    continue
                v = _pass_check(own, zf, parent, height, depth, tol, a, bi * nx + bj)
                if v == v:
                    keys = _grow(keys, nk)
                    vals = _grow(vals, nk)
                    keys[nk] = d * size + a
                    vals[nk] = v
                    nk += 1
    order = np.argsort(keys[:nk])
    oa = np.empty(nk, np.int64)
    ob = np.empty(nk, np.int64)
    ov = np.empty(nk, np.float64)
    for t in range(nk):
        key = keys[order[t]]
        d = key // size
        a = key - d * size
        oa[t] = a
        ob[t] = a + (1 if d == 0 else nx + d - 2)
        ov[t] = vals[order[t]]
    return oa, ob, ov


@njit(cache=True, nogil=True)
def _resolve_basins(ptr: np.ndarray, lab: np.ndarray, own: np.ndarray, tid: np.ndarray, cells: np.ndarray,
                    peak_cells: np.ndarray, peak_ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Basin and owner of the ``cells`` whose ``lab`` is -3 (unresolved), by following their pointers
    to a resolved cell or a new maximum (next basin id, its tree peak from ``peak_cells`` /
    ``peak_ids``, -1 if none); returns the new maxima's cells and owners."""
    n0 = tid.size
    new_top = np.empty(16, np.int64)
    new_tid = np.empty(16, np.int64)
    nn = 0
    stack = np.empty(1024, np.int64)
    for t in range(cells.size):
        j = cells[t]
        if lab[j] != -3:
            continue
        top = 0
        while lab[j] == -3:
            stack = _grow(stack, top)
            stack[top] = j
            top += 1
            if ptr[j] == j:  # a new maximum
                new_top = _grow(new_top, nn)
                new_tid = _grow(new_tid, nn)
                k = np.searchsorted(peak_cells, j)
                new_top[nn] = j
                new_tid[nn] = peak_ids[k] if k < peak_cells.size and peak_cells[k] == j else -1
                lab[j] = n0 + nn
                nn += 1
                break
            j = ptr[j]
        v = lab[j]
        o = tid[v] if v < n0 else new_tid[v - n0]
        for s in range(top):
            lab[stack[s]] = v
            own[stack[s]] = o
    return new_top[:nn].copy(), new_tid[:nn].copy()


@njit(cache=True, nogil=True, parallel=True)
def relabel_basins(z: np.ndarray, ptr: np.ndarray, lab: np.ndarray, own: np.ndarray, tid: np.ndarray,
                   cells: np.ndarray, peak_cells: np.ndarray, peak_ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`update_basins` when the caller knows the cells that may change basin: new pointers for
    the ``cells`` (flat, distinct; on all threads) and their basins by following them (one thread);
    every other cell must keep its pointer and its chain must stay outside ``cells`` (true after
    cutting whole basins down: a cell outside them points to a higher cell of its own basin, still
    higher)."""
    H, W = z.shape
    for t in prange(cells.size):
        j = cells[t]
        r = j // W
        p = ascent_pointer(z, r, j - r * W)
        ptr[j] = p
        if p < 0:
            lab[j] = -1
            own[j] = -2
        else:
            lab[j] = -3
    return _resolve_basins(ptr, lab, own, tid, cells, peak_cells, peak_ids)


@njit(cache=True, nogil=True, parallel=True)
def slope_magnitude(z: np.ndarray, res: np.float32) -> np.ndarray:
    """``np.hypot(gx, gy)`` of ``gy, gx = np.gradient(z, res)`` for a float32 ``z`` (at least 2 x 2) and
    float32 ``res``: the same float32 operations (central differences divided by ``2 res``, one-sided ones
    by ``res`` on the edges; the C library's ``hypotf``, as numpy's), without the two gradient rasters
    (rows on all threads)."""
    ny, nx = z.shape
    out = np.empty((ny, nx), np.float32)
    two = np.float32(2.0) * res
    for i in prange(ny):
        for j in range(nx):
            if i == 0:
                gy = (z[1, j] - z[0, j]) / res
            elif i == ny - 1:
                gy = (z[ny - 1, j] - z[ny - 2, j]) / res
            else:
                gy = (z[i + 1, j] - z[i - 1, j]) / two
            if j == 0:
                gx = (z[i, 1] - z[i, 0]) / res
            elif j == nx - 1:
                gx = (z[i, nx - 1] - z[i, nx - 2]) / res
            else:
                gx = (z[i, j + 1] - z[i, j - 1]) / two
            out[i, j] = math.hypot(gx, gy)
    return out


@njit(cache=True, nogil=True, parallel=True)
def flat_ramp(s: np.ndarray, t: np.float32) -> np.ndarray:
    """``np.clip((minimum_filter(s, size=3, mode="nearest") - t) / t, 0, 1)`` for a float32 ``s`` without
    NaN and a float32 ``t``: 0 where the least slope of a cell and its 8 neighbours is ``t`` or less,
    rising linearly to 1 at ``2 t`` (the same float32 operations; rows on all threads)."""
    ny, nx = s.shape
    out = np.empty((ny, nx), np.float32)
    for i in prange(ny):
        i0 = max(i - 1, 0)
        i1 = min(i + 1, ny - 1)
        col = np.empty(nx, np.float32)  # least of the three rows in each column
        for j in range(nx):
            col[j] = min(s[i0, j], s[i, j], s[i1, j])
        for j in range(nx):
            m = min(col[max(j - 1, 0)], col[j], col[min(j + 1, nx - 1)])
            v = (m - t) / t
            out[i, j] = np.float32(0.0) if v < 0 else (np.float32(1.0) if v > 1 else v)
    return out


@njit(cache=True, nogil=True, parallel=True)
def gaussian_nearest(s: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``scipy.ndimage.gaussian_filter(s, sigma, mode="nearest")`` of a float32 ``s`` given its symmetric
    1-D weights ``w`` (odd size, :func:`orokit.raster.render._gaussian_weights`): rows, then columns,
    each pass as scipy's ``correlate1d`` computes a symmetric filter (float64 sums in the same order,
    ``x[0] w[0] + sum (x[-k] + x[k]) w[-k]`` from the outermost pair in, rounded to float32 after each
    pass); rows of cells on all threads."""
    ny, nx = s.shape
    r = w.size // 2
    tmp = np.empty((ny, nx), np.float32)
    for i in prange(ny):
        acc = np.empty(nx, np.float64)
        for j in range(nx):
            acc[j] = np.float64(s[i, j]) * w[r]
        for k in range(-r, 0):
            ia = min(max(i + k, 0), ny - 1)
            ib = min(max(i - k, 0), ny - 1)
            wk = w[r + k]
            for j in range(nx):
                acc[j] += (np.float64(s[ia, j]) + np.float64(s[ib, j])) * wk
        for j in range(nx):
            tmp[i, j] = np.float32(acc[j])
    out = np.empty((ny, nx), np.float32)
    for i in prange(ny):
        line = np.empty(nx + 2 * r, np.float64)
        for j in range(nx + 2 * r):
            line[j] = np.float64(tmp[i, min(max(j - r, 0), nx - 1)])
        for j in range(nx):
            a = line[j + r] * w[r]
            for k in range(-r, 0):
                a += (line[j + r + k] + line[j + r - k]) * w[r + k]
            out[i, j] = np.float32(a)
    return out
