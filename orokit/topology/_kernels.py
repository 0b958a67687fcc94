"""Numerical kernels of the exact orometry engine (numba).

Everything here works on flat numpy arrays and scalars only. Cells (and peaks,
saddles) are compared in a *strict total order*: ``a`` is above ``b`` when
``z[a] > z[b]``, or when ``z[a] == z[b]`` and ``key[a] < key[b]``. ``key`` is the
flat raster index for cells (so the first cell in raster order wins ties, which makes
the first cell of a flat summit its representative) and the id for tree nodes.

numba is used because the work is sequential by nature (chain following, union-find,
Kruskal sweeps, hashing of basin pairs): numpy cannot express these without
Python-level loops, and a single compiled pass over the neighbours keeps the raster
engine at several million cells per second.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

_NEIGHBOURS_8 = ((-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1))
# each unordered neighbour pair once: E, SW, S, SE
_FORWARD_4 = ((0, 1), (1, -1), (1, 0), (1, 1))


@njit(cache=True, nogil=True, inline="always")
def above(za, ka, zb, kb):
    """True when (za, ka) is above (zb, kb) in the total order."""
    return za > zb or (za == zb and ka < kb)


@njit(cache=True, nogil=True, inline="always")
def ascent_pointer(z, r, c):
    """Flat index of the highest 8-neighbour of cell ``(r, c)`` of ``z`` in the total order
    (elevation, then raster order: earlier is higher), the cell itself when none is above it,
    -1 for a NaN cell; cells outside the raster and NaN cells are skipped."""
    H, W = z.shape
    zi = z[r, c]
    if zi != zi:
        return -1
    best = r * W + c
    bz = zi
    for dr in range(-1, 2):
        rr = r + dr
        if rr < 0 or rr >= H:
            continue
        for dc in range(-1, 2):
            cc = c + dc
            if (dr == 0 and dc == 0) or cc < 0 or cc >= W:
                continue
            zn = z[rr, cc]
            if zn != zn:
                continue
            j = rr * W + cc
            if zn > bz or (zn == bz and j < best):
                best = j
                bz = zn
    return best


@njit(cache=True, nogil=True, inline="always")
def point_chain_at_end(lab, i, stack):
    """Follow the pointers ``lab`` from cell ``i`` (``lab[i] >= 0``) to the chain's end (the first
    negative value) and write that value into every cell on the way; ``stack`` is scratch space,
    returned (grown when the chain is longer)."""
    v = lab[i]
    top = 0
    j = i
    while v >= 0:
        if top == stack.size:
            bigger = np.empty(stack.size * 2, np.int64)
            bigger[:top] = stack[:top]
            stack = bigger
        stack[top] = j
        top += 1
        j = v
        v = lab[j]
    for t in range(top):
        lab[stack[t]] = v
    return stack


@njit(cache=True, nogil=True)
def steepest_ascent(zh):
    """Pointer of every cell to its highest 8-neighbour, exits and border flags.

    ``zh`` is the raster (or a chunk of it) with a one-cell halo all round: NaN
    outside the raster, neighbouring values around a chunk. Every cell of the core
    ``zh[1:-1, 1:-1]`` points to its highest neighbour in the whole raster's total
    order, halo included, so chains follow the raster's own steepest ascent; a chain
    that leaves the core ends at an *exit* cell (its highest neighbour lies in the
    halo). Cells next to a NaN cell are "border" cells (so raster-edge cells are).

    Returns ``ptr`` (flat core index of the highest neighbour if it is in the core and
    above the cell, the cell itself for a local maximum or an exit, -1 for NaN cells),
    ``exit_to`` (flat index in ``zh`` of the halo cell an exit points to, else -1) and
    ``border``. Tie-break keys are positions in ``zh`` (row, then column), which order
    cells exactly as the whole raster's order does.
    """
    Hh, Wh = zh.shape
    h = Hh - 2
    w = Wh - 2
    n = h * w
    ptr = np.empty(n, np.int64)
    exit_to = np.full(n, -1, np.int64)
    border = np.zeros(n, np.bool_)
    for r in range(h):
        for c in range(w):
            i = r * w + c
            zi = zh[r + 1, c + 1]
            if zi != zi:
                ptr[i] = -1
                continue
            me = (r + 1) * Wh + c + 1
            best = me
            bz = zi
            isb = False
            for d in _NEIGHBOURS_8:
                rr = r + 1 + d[0]
                cc = c + 1 + d[1]
                zn = zh[rr, cc]
                if zn != zn:
                    isb = True
                    continue
                j = rr * Wh + cc
                if zn > bz or (zn == bz and j < best):
                    best = j
                    bz = zn
            border[i] = isb
            if best == me:
                ptr[i] = i
                continue
            br = best // Wh - 1
            bc = best % Wh - 1
            if br < 0 or br >= h or bc < 0 or bc >= w:
                ptr[i] = i
                exit_to[i] = best
            else:
                ptr[i] = br * w + bc
    return ptr, exit_to, border


@njit(cache=True, nogil=True)
def label_basins(ptr):
    """Label every cell with the id of the end (maximum or exit) its ascent chain reaches.

    Chain ends (``ptr[i] == i``) get ids 0..n-1 in raster order. Returns ``label``
    (-1 for NaN cells) and ``peak_cell`` (flat index of each chain end).
    """
    n = ptr.size
    label = np.full(n, -1, np.int64)
    npk = 0
    for i in range(n):
        if ptr[i] == i:
            label[i] = npk
            npk += 1
    peak_cell = np.empty(npk, np.int64)
    k = 0
    for i in range(n):
        if ptr[i] == i:
            peak_cell[k] = i
            k += 1
    stack = np.empty(1024, np.int64)
    for i in range(n):
        if label[i] >= 0 or ptr[i] < 0:
            continue
        top = 0
        j = i
        while label[j] < 0:
            if top == stack.size:
                bigger = np.empty(stack.size * 2, np.int64)
                bigger[:top] = stack[:top]
                stack = bigger
            stack[top] = j
            top += 1
            j = ptr[j]
        lab = label[j]
        for t in range(top):
            label[stack[t]] = lab
    return label, peak_cell


@njit(cache=True, nogil=True, parallel=True)
def ascent_labels(z, lab, ptr=None):
    """Basins of steepest ascent of a whole raster, in place and in parallel row blocks.

    Same pointers as :func:`steepest_ascent` on the raster padded with NaN (outside the
    raster counts as nodata), without the padded copy. ``lab`` (int32 or int64, size
    ``z.size``) first holds each cell's pointer, then, chain by chain, the encoded id
    ``-2 - k`` of the maximum it reaches; threads may meet on a chain, and a cell holds
    either a pointer up its chain or that chain's final id, so every reader sees a
    valid state. On return ``lab`` holds basin ids 0..n-1 (maxima in raster order) and
    -1 for NaN cells. Returns the flat cell of each maximum. ``ptr`` (int64, size
    ``z.size``), if given, receives every cell's :func:`ascent_pointer` as it is computed.
    """
    H, W = z.shape
    nb = min(H, 256)
    counts = np.zeros(nb + 1, np.int64)
    for b in prange(nb):
        r0 = b * H // nb
        r1 = (b + 1) * H // nb
        cnt = 0
        for r in range(r0, r1):
            for c in range(W):
                i = r * W + c
                best = ascent_pointer(z, r, c)
                if ptr is not None:
                    ptr[i] = best
                if best < 0:
                    lab[i] = -1
                    continue
                if best == i:
                    lab[i] = -2
                    cnt += 1
                else:
                    lab[i] = best
        counts[b + 1] = cnt
    for b in range(nb):
        counts[b + 1] += counts[b]
    peak_cell = np.empty(counts[nb], np.int64)
    for b in prange(nb):
        k = counts[b]
        for i in range((b * H // nb) * W, ((b + 1) * H // nb) * W):
            if lab[i] == -2:
                lab[i] = -2 - k
                peak_cell[k] = i
                k += 1
    for b in prange(nb):
        stack = np.empty(1024, np.int64)
        for i in range((b * H // nb) * W, ((b + 1) * H // nb) * W):
            if lab[i] >= 0:
                stack = point_chain_at_end(lab, i, stack)
    for b in prange(nb):
        for i in range((b * H // nb) * W, ((b + 1) * H // nb) * W):
            v = lab[i]
            if v <= -2:
                lab[i] = -2 - v
    return peak_cell


@njit(cache=True, nogil=True)
def basin_border_max(z, label, border, npk):
    """Highest border-cell elevation of every basin (-inf when it has none)."""
    out = np.full(npk, -np.inf)
    zf = z.ravel()
    for i in range(label.size):
        if border[i]:
            lab = label[i]
            if zf[i] > out[lab]:
                out[lab] = zf[i]
    return out


@njit(cache=True, nogil=True)
def _hash_slot(key, mask):
    h = np.uint64(key) * np.uint64(0x9E3779B97F4A7C15)
    return np.int64((h >> np.uint64(17)) & np.uint64(mask))


@njit(cache=True, nogil=True)
def _insert(keys, vals, key, cell, zf):
    mask = keys.size - 1
    s = _hash_slot(key, mask)
    while True:
        k = keys[s]
        if k == -1:
            keys[s] = key
            vals[s] = cell
            return 1
        if k == key:
            old = vals[s]
            if above(zf[cell], cell, zf[old], old):
                vals[s] = cell
            return 0
        s = (s + 1) & mask


@njit(cache=True, nogil=True)
def _grow_pass_table(keys, vals, zf):
    """The open-addressing pass table at twice its size, entries re-inserted."""
    new_k = np.full(keys.size * 2, -1, np.int64)
    new_v = np.empty(keys.size * 2, vals.dtype)
    for s in range(keys.size):
        if keys[s] != -1:
            _insert(new_k, new_v, keys[s], vals[s], zf)
    return new_k, new_v


@njit(cache=True, nogil=True)
def _unpack_pass_table(keys, vals, count, npk):
    """(basin a, basin b, pass cell) of every entry of the pass table, in slot order."""
    ea = np.empty(count, np.int64)
    eb = np.empty(count, np.int64)
    ec = np.empty(count, np.int64)
    k = 0
    for s in range(keys.size):
        if keys[s] != -1:
            ea[k] = keys[s] // npk
            eb[k] = keys[s] % npk
            ec[k] = vals[s]
            k += 1
    return ea, eb, ec


@njit(cache=True, nogil=True)
def basin_passes(z, label, npk):
    """Highest pass between every pair of adjacent basins.

    For each pair of 8-adjacent valid cells in different basins the pass value is the
    lower of the two cells (total order); the pass of a basin pair is the highest such
    value. Returns arrays ``(basin_a, basin_b, pass_cell)`` with basin_a < basin_b.
    """
    H, W = z.shape
    zf = z.ravel()
    size = 1024
    while size < 8 * npk:
        size *= 2
    keys = np.full(size, -1, np.int64)
    vals = np.empty(size, np.int64)
    count = 0
    for r in range(H):
        for c in range(W):
            i = r * W + c
            la = label[i]
            if la < 0:
                continue
            for d in _FORWARD_4:
                rr = r + d[0]
                cc = c + d[1]
                if rr >= H or cc < 0 or cc >= W:
                    continue
                j = rr * W + cc
                lb = label[j]
                if lb < 0 or lb == la:
                    continue
                p = j if above(zf[i], i, zf[j], j) else i
                if la < lb:
                    key = la * npk + lb
                else:
                    key = lb * npk + la
                count += _insert(keys, vals, key, p, zf)
                if 2 * count > keys.size:
                    keys, vals = _grow_pass_table(keys, vals, zf)
    ea, eb, ec = _unpack_pass_table(keys, vals, count, npk)
    return ea, eb, ec


@njit(cache=True, nogil=True)
def _find(parent, x):
    root = x
    while parent[root] != root:
        root = parent[root]
    while parent[x] != root:
        nxt = parent[x]
        parent[x] = root
        x = nxt
    return root


@njit(cache=True, nogil=True)
def forest_components(n, ea, eb):
    """Component (a root node id) of every node of the graph with edges ``ea``-``eb``."""
    return forest_components_like(n, ea, eb, np.empty(0, np.bool_), np.empty(0, np.int64))


@njit(cache=True, nogil=True)
def forest_components_like(n, ea, eb, use, like):
    """:func:`forest_components` of the edges where ``use`` is True (all when ``use`` is empty: no
    copies of the edges taken), with the union-find state and the output in ``like``'s integer type
    (:func:`index_like`)."""
    uf = np.empty(n, like.dtype)
    for i in range(n):
        uf[i] = i
    every = use.size == 0
    for e in range(ea.size):
        if not every and not use[e]:
            continue
        ra = _find(uf, ea[e])
        rb = _find(uf, eb[e])
        if ra != rb:
            uf[rb] = ra
    for i in range(n):  # in place: the roots first found stay roots
        uf[i] = _find(uf, i)
    return uf


@njit(cache=True, nogil=True)
def flat_roots(dom, nmin, z, is_root):
    """Per node: a domain root (``is_root``) whose domain's lowest value (``nmin`` over the nodes of
    its domain, ``dom`` from :func:`forest_components_like`) is not below its elevation ``z``: a flat
    domain, whose cells all have the root's elevation (NaN propagates as in ``np.minimum``)."""
    n = dom.size
    dmin = np.full(n, np.inf)
    for i in range(n):
        v = nmin[i]
        d = dom[i]
        if v < dmin[d] or v != v:
            if dmin[d] == dmin[d]:
                dmin[d] = v
    out = np.zeros(n, np.bool_)
    for i in range(n):
        out[i] = is_root[i] and dmin[dom[i]] >= z[i]
    return out


@njit(cache=True, nogil=True)
def kruskal_sweep(node_z, node_key, ea, eb, ez, ekey, border_z):
    """:func:`kruskal_sweep_like` with int64 state and outputs."""
    return kruskal_sweep_like(node_z, node_key, ea, eb, ez, ekey, border_z, np.empty(0, np.int64))


@njit(cache=True, nogil=True)
def kruskal_sweep_like(node_z, node_key, ea, eb, ez, ekey, border_z, like):
    """Maximum spanning forest and elder-rule prominence in one Kruskal sweep.

    Edges must be sorted from the highest to the lowest saddle in the total order
    (elevation descending, then ``ekey`` ascending). Consecutive edges with the same
    ``ekey`` share one saddle cell (a "monkey saddle" joining several basins): they
    are merged as one event, so the result does not depend on how a graph lists them.
    At each event every component whose top (highest node) is not the highest top of
    the merged group dies: the event is its key saddle and the group's highest top is
    its parent (its island parent: the highest peak it joins at that level).

    Parameters
    ----------
    node_z, node_key : elevation and tie-break key of every node.
    ea, eb : endpoints of each edge (sorted, see above); ez, ekey : saddle elevation
        and saddle key of each edge.
    border_z : highest "border" elevation of every node's basin (-inf if none). A
        dying component whose border is reachable from its top strictly above the saddle
        (bottleneck, carried through the merges) touched the
        edge of the data above the key saddle: its prominence is only an upper bound.

    Returns
    -------
    in_tree : bool per edge (False for edges closing a cycle).
    key_edge : per node, index of its key-saddle edge (-1 for domain roots).
    parent : per node, top of the group it merged into (-1 for roots).
    touched : per node, border flag described above (roots: True if their domain has
        any border cell).

    ``like``: an empty array whose integer type the union-find state, ``key_edge`` and ``parent``
    take (:func:`index_like`: int32 below 2**31 nodes and edges, 16 bytes per node less than int64).
    """
    n = node_z.size
    m = ea.size
    uf = np.empty(n, like.dtype)
    top = np.empty(n, like.dtype)
    key_edge = np.empty(n, like.dtype)
    parent = np.empty(n, like.dtype)
    for i in range(n):
        uf[i] = i
        top[i] = i
        key_edge[i] = -1
        parent[i] = -1
    bmax = border_z.copy()
    touched = np.zeros(n, np.bool_)
    in_tree = np.zeros(m, np.bool_)
    roots = np.empty(16, np.int64)
    tops = np.empty(16, np.int64)
    bms = np.empty(16, np.float64)
    e = 0
    while e < m:
        f = e + 1
        while f < m and ekey[f] == ekey[e]:
            f += 1
        # distinct components touched by the event, before merging
        k = 0
        for g in range(e, f):
            for x in (ea[g], eb[g]):
                r = _find(uf, x)
                seen = False
                for t in range(k):
                    if roots[t] == r:
                        seen = True
                        break
                if not seen:
                    if k == roots.size:
                        roots = np.concatenate((roots, np.empty(k, np.int64)))
                        tops = np.concatenate((tops, np.empty(k, np.int64)))
                        bms = np.concatenate((bms, np.empty(k, np.float64)))
                    roots[k] = r
                    tops[k] = top[r]
                    bms[k] = bmax[r]
                    k += 1
        for g in range(e, f):
            ra = _find(uf, ea[g])
            rb = _find(uf, eb[g])
            if ra == rb:
                continue
            in_tree[g] = True
            uf[rb] = ra
            ta = top[ra]
            tb = top[rb]
            # bmax of a component: the highest level at which its top reaches the border
            # (bottleneck); the losing side's border is reached through this saddle only
            w = ez[g]
            if above(node_z[ta], node_key[ta], node_z[tb], node_key[tb]):
                bmax[ra] = max(bmax[ra], min(bmax[rb], w))
            else:
                top[ra] = tb
                bmax[ra] = max(min(bmax[ra], w), bmax[rb])
        for t in range(k):
            w = top[_find(uf, roots[t])]
            if tops[t] != w:
                lose = tops[t]
                key_edge[lose] = e
                parent[lose] = w
                touched[lose] = bms[t] > ez[e]
        e = f
    for i in range(n):
        if key_edge[i] < 0:
            touched[i] = bmax[_find(uf, i)] > -np.inf
    return in_tree, key_edge, parent, touched


@njit(cache=True, nogil=True)
def saddle_key(up, ekey, ez):
    """One 64-bit sort key per edge of a saddle graph (elevation descending, then ``ekey``), or an
    empty array when ``ekey`` does not fit in 32 bits.

    ``up``: the elevations as float32 bits mapped to unsigned integers that increase with the
    elevation. ``ekey`` must lie in ``[0, 2**32)``, except on the edges above every saddle
    (``ez`` = +inf), which sort first and whose keys must all lie in ``[0, 2**32)`` or all in
    ``[-2**32, 0)`` (a side cell's tie to its basin, key ``-1 - cell``): a key's low 32 bits
    then keep their order.
    """
    m = ekey.size
    lo = np.int64(0)
    hi = np.int64(-1)
    seen = False
    for i in range(m):
        k = ekey[i]
        if ez[i] == np.inf:
            if not seen or k < lo:
                lo = k
            if not seen or k > hi:
                hi = k
            seen = True
        elif k < 0 or k >= 2**32:
            return np.empty(0, np.uint64)
    if seen and not ((lo >= 0 and hi < 2**32) or (lo >= -2**32 and hi < 0)):
        return np.empty(0, np.uint64)
    key = np.empty(m, np.uint64)
    mask = np.int64(0xFFFFFFFF)
    for i in range(m):
        key[i] = (np.uint64(0xFFFFFFFF - up[i]) << np.uint64(32)) | np.uint64(ekey[i] & mask)
    return key


#: bits per digit of :func:`radix_argsort` (2048 buckets: the counts and the write positions stay in cache)
_RADIX_BITS = 11


@njit(cache=True, nogil=True)
def radix_argsort(key):
    """Stable argsort of the uint64 ``key`` (least significant digit first, digits of
    :data:`_RADIX_BITS` bits; a digit every key shares is skipped); ``key`` is sorted in place.
    Two buffers of ``key``'s size (16 bytes per key) are held meanwhile."""
    n = key.size
    order = np.arange(n)
    if n < 2:
        return order
    nbits = _RADIX_BITS
    radix = 1 << nbits
    npass = (64 + nbits - 1) // nbits
    mask = np.uint64(radix - 1)
    hist = np.zeros((npass, radix), np.int64)
    for i in range(n):
        k = key[i]
        for p in range(npass):
            hist[p, np.int64((k >> np.uint64(p * nbits)) & mask)] += 1
    buf_k = np.empty(n, np.uint64)
    buf_o = np.empty(n, np.int64)
    src_k, src_o, dst_k, dst_o = key, order, buf_k, buf_o
    pos = np.empty(radix, np.int64)
    for p in range(npass):
        shift = np.uint64(p * nbits)
        if hist[p, np.int64((src_k[0] >> shift) & mask)] == n:
            continue
        total = 0
        for d in range(radix):
            pos[d] = total
            total += hist[p, d]
        for i in range(n):
            k = src_k[i]
            d = np.int64((k >> shift) & mask)
            j = pos[d]
            pos[d] = j + 1
            dst_k[j] = k
            dst_o[j] = src_o[i]
        src_k, dst_k = dst_k, src_k
        src_o, dst_o = dst_o, src_o
    if src_k is not key:
        key[:] = src_k
    return src_o


@njit(cache=True, nogil=True)
def merge_sorted_halves(key, first, second, h):
    """The stable argsort of ``key`` from its two halves ``key[:h]`` and ``key[h:]``, each sorted in place with
    ``first`` and ``second`` its stable argsort (:func:`radix_argsort`; ``second`` counts from ``h``); ``key``
    merged in place (a copy of its first half held meanwhile). Equal keys: the first half's first."""
    n = key.size
    a = key[:h].copy()
    order = np.empty(n, np.int64)
    i = 0
    j = h
    k = 0
    while i < h and j < n:  # k = i + j - h < j: no key of the second half is written over before it is read
        if key[j] < a[i]:
            key[k] = key[j]
            order[k] = second[j - h] + h
            j += 1
        else:
            key[k] = a[i]
            order[k] = first[i]
            i += 1
        k += 1
    while i < h:
        key[k] = a[i]
        order[k] = first[i]
        i += 1
        k += 1
    while j < n:  # the second half's rest is in place already
        order[k] = second[j - h] + h
        j += 1
        k += 1
    return order


@njit(cache=True, nogil=True)
def sort_saddle_ties(order, key, ea, eb, in_order=False):
    """Within each run of equal ``key[order]`` (edges of one saddle cell), ``order`` rearranged in place
    by ``(ea, eb)``, then by index (a stable lexsort's order); ``ea``, ``eb`` in ``[0, 2**31)``.
    ``in_order``: ``key`` is already in ``order``'s order (sorted)."""
    m = order.size
    i = 0
    while i < m:
        k = key[i] if in_order else key[order[i]]
        j = i + 1
        while j < m and (key[j] if in_order else key[order[j]]) == k:
            j += 1
        if j - i > 1:
            sub = np.sort(order[i:j])
            pair = np.empty(j - i, np.int64)
            for t in range(j - i):
                pair[t] = (np.int64(ea[sub[t]]) << 32) | np.int64(eb[sub[t]])
            rank = np.argsort(pair, kind="mergesort")
            for t in range(j - i):
                order[i + t] = sub[rank[t]]
        i = j


@njit(cache=True, nogil=True, inline="always")
def _node_before(x, y, node_z, node_key):
    """x before y in a decreasing order of nodes, -1 (none) last."""
    if x == y:
        return False
    if y < 0:
        return True
    if x < 0:
        return False
    return above(node_z[x], node_key[x], node_z[y], node_key[y])


@njit(cache=True, nogil=True)
def _before(g, h, key_t, key_hi, key_lo, node_z, node_key):
    """Edge g goes before edge h at one saddle (see :func:`prune_edges`; g, h index the saddle's edges)."""
    for keys in (key_t, key_hi, key_lo):
        if keys[g] != keys[h]:
            return _node_before(keys[g], keys[h], node_z, node_key)
    return g < h


def index_like(n: int, m: int = 0) -> np.ndarray:
    """An empty array of the narrowest index type for ``n`` nodes and ``m`` edges (int32 below 2**31):
    the dtype :func:`prune_edges` gives its union-find state and its output indices."""
    return np.empty(0, np.int32 if max(n, m) < 2**31 - 1 else np.int64)


@njit(cache=True, nogil=True)
def prune_edges(n, ea, eb, ez, ekey, keep, bmax, nmin, node_z, node_key, defer, like):
    """Divide Tree restricted to the kept nodes, preserving bottleneck saddles.

    Edges (of any graph) must be sorted from the highest to the lowest saddle, those
    of one saddle (same ``ekey``) consecutive; edges closing a cycle are skipped. The
    result is the maximum spanning
    forest of the kept nodes under bottleneck (max-min) saddle heights, so every kept
    node keeps its prominence and key saddle when all removed nodes have a lower
    prominence than all kept ones. A removed node is absorbed into the neighbour
    across its highest saddle (star contraction), which keeps ridges between
    geographic neighbours. When one saddle joins several parts holding kept nodes, a
    part without any is absorbed into the one whose top (highest node, in the order
    ``node_z`` then ``node_key``) is highest: the edges of one saddle are taken by
    decreasing top of their parts with kept nodes, so the pruned tree does not depend
    on how the graph lists them (the in-memory and the chunked engines agree); among
    edges of one saddle joining the same two parts, the one whose kept ends are
    highest is the ridge.

    ``defer`` (chunk summaries, whose kept set is larger than the final one): a
    removed part of a saddle with two or more edges reaching kept parts is not
    absorbed but kept (its first node), and every edge of one
    saddle between kept parts is returned, so the choices are made once the final
    kept set is known.

    ``bmax`` (highest border elevation reachable in a node's basin) and ``nmin``
    (lowest elevation of the basin) are carried to the node a removed node is
    absorbed into; the border value through the absorbing saddle ``w`` is
    ``min(bmax, w)``, which keeps the "touched the unknown outside" flags exact. With
    ``defer`` the carried values are written over ``bmax`` and ``nmin`` (returned as
    ``bmax_new`` and ``nmin_new``: a caller passes arrays it gives up).

    Returns ``(out_a, out_b, out_edge, bmax_new, nmin_new, keep_new)``: kept endpoints
    and the index of the original edge (its saddle) of each output ridge, the carried
    per-node values (meaningful at kept nodes; empty without ``defer``) and the kept
    nodes (``keep`` plus the deferred ones).

    ``like``: an empty array whose integer type the union-find state and the three output index
    arrays take (:func:`index_like`: int32 below 2**31 nodes and edges, 12 bytes per node and per
    edge less at a 6.5 M-node root than int64).
    """
    uf = np.empty(n, like.dtype)
    top = np.empty(n, like.dtype)
    anchor = np.empty(n, like.dtype)  # anchor forest: a node points towards the kept node it is absorbed into
    for i in range(n):
        uf[i] = i
        top[i] = i
        anchor[i] = i
    keep = keep.copy()
    haskept = keep.copy()
    # the carried values matter only to a later merge: the final prune (not ``defer``) returns them
    # empty and skips them (32 bytes per node at the finalize of a 6.5 M-node root)
    carry = n if defer else 0
    comp_b = bmax[:carry].copy()
    comp_m = nmin[:carry].copy()
    # the carried values are written over ``bmax`` and ``nmin`` (read only for the copies above)
    nb = bmax[:carry]
    nm = nmin[:carry]
    out_a = np.empty(ea.size, like.dtype)
    out_b = np.empty(ea.size, like.dtype)
    out_e = np.empty(ea.size, like.dtype)
    # per edge of the current saddle (index g - e), grown to the largest saddle: not per edge of
    # the graph (16-40 bytes per edge at the top merges and the finalize of a 4 G-cell mosaic)
    pre_a = np.empty(16, np.int64)
    pre_b = np.empty(16, np.int64)
    key_t = np.empty(16, np.int64)
    key_hi = np.empty(16, np.int64)
    key_lo = np.empty(16, np.int64)
    k = 0
    e = 0
    while e < ea.size:
        f = e + 1
        while f < ea.size and ekey[f] == ekey[e]:
            f += 1
        if f - e > pre_a.size:
            cap = max(f - e, 2 * pre_a.size)
            pre_a = np.empty(cap, np.int64)
            pre_b = np.empty(cap, np.int64)
            key_t = np.empty(cap, np.int64)
            key_hi = np.empty(cap, np.int64)
            key_lo = np.empty(cap, np.int64)
        for g in range(e, f):
            pre_a[g - e] = _find(uf, ea[g])
            pre_b[g - e] = _find(uf, eb[g])
        seq = np.arange(e, f)
        if f - e > 1:
            if defer:
                n_kept_parts = 0
                n_bare = 0
                roots = np.empty(2 * (f - e), np.int64)
                m = 0
                for g in range(e, f):
                    for r in (pre_a[g - e], pre_b[g - e]):
                        seen = False
                        for t in range(m):
                            if roots[t] == r:
                                seen = True
                        if not seen:
                            roots[m] = r
                            m += 1
                for t in range(m):
                    if not haskept[roots[t]]:
                        n_bare += 1
                for g in range(e, f):
                    if haskept[pre_a[g - e]] or haskept[pre_b[g - e]]:
                        n_kept_parts += 1  # edges reaching a kept part
                if n_kept_parts >= 2 and n_bare >= 1:
                    for t in range(m):
                        r = roots[t]
                        if not haskept[r]:
                            d = _find(anchor, r)
                            keep[d] = True
                            haskept[r] = True
                            nb[d] = max(nb[d], comp_b[r])
                            nm[d] = min(nm[d], comp_m[r])
            # order of the saddle's edges: decreasing top of their kept parts, then
            # decreasing kept ends (higher, then lower), then edge order
            for g in range(e, f):
                best = -1
                hi = -1
                lo = -1
                for side in range(2):
                    r = pre_a[g - e] if side == 0 else pre_b[g - e]
                    x = ea[g] if side == 0 else eb[g]
                    if not haskept[r]:
                        continue
                    t = top[r]
                    if best < 0 or above(node_z[t], node_key[t], node_z[best], node_key[best]):
                        best = t
                    y = _find(anchor, x)
                    if hi < 0 or above(node_z[y], node_key[y], node_z[hi], node_key[hi]):
                        lo = hi
                        hi = y
                    else:
                        lo = y
                key_t[g - e] = best
                key_hi[g - e] = hi
                key_lo[g - e] = lo
            for i in range(1, f - e):
                g = seq[i]
                j = i - 1
                while j >= 0 and _before(g - e, seq[j] - e, key_t, key_hi, key_lo, node_z, node_key):
                    seq[j + 1] = seq[j]
                    j -= 1
                seq[j + 1] = g
        for g in seq:
            a = ea[g]
            b = eb[g]
            ra = _find(uf, a)
            rb = _find(uf, b)
            if ra == rb:
                # a second edge of this saddle between two parts it already joined: kept
                # while deferring (the final prune chooses among them)
                if defer and pre_a[g - e] != pre_b[g - e] and haskept[ra]:
                    x = _find(anchor, a)
                    y = _find(anchor, b)
                    if x != y and keep[x] and keep[y]:
                        out_a[k] = x
                        out_b[k] = y
                        out_e[k] = g
                        k += 1
                continue
            if haskept[ra] and haskept[rb]:
                out_a[k] = _find(anchor, a)
                out_b[k] = _find(anchor, b)
                out_e[k] = g
                k += 1
            elif haskept[rb] or haskept[ra]:
                # the component without a kept node is absorbed across this saddle
                if haskept[rb]:
                    src, dst = ra, _find(anchor, b)
                else:
                    src, dst = rb, _find(anchor, a)
                if defer:
                    nb[dst] = max(nb[dst], min(comp_b[src], ez[g]))
                    nm[dst] = min(nm[dst], comp_m[src])
                anchor[_find(anchor, src)] = dst
            else:
                anchor[_find(anchor, rb)] = _find(anchor, ra)
                if defer:
                    comp_b[ra] = max(comp_b[ra], comp_b[rb])
                    comp_m[ra] = min(comp_m[ra], comp_m[rb])
            ta = top[ra]
            tb = top[rb]
            uf[rb] = ra
            if above(node_z[tb], node_key[tb], node_z[ta], node_key[ta]):
                top[ra] = tb
            haskept[ra] = haskept[ra] or haskept[rb]
        e = f
    return out_a[:k], out_b[:k], out_e[:k], nb, nm, keep


@njit(cache=True, nogil=True)
def basin_min(z, label, npk):
    """Lowest elevation of every basin."""
    out = np.full(npk, np.inf)
    zf = z.ravel()
    for i in range(label.size):
        lab = label[i]
        if lab >= 0 and zf[i] < out[lab]:
            out[lab] = zf[i]
    return out


@njit(cache=True, nogil=True)
def line_parents(rank, ea, eb):
    """Line parent of every node of a tree (forest), in one Kruskal sweep.

    ``rank`` orders the nodes (larger = higher, all distinct); ``ea``/``eb`` are the
    tree edges sorted from the highest to the lowest saddle (any integer type: the union-find
    state takes theirs). When two components meet,
    the one with the lower top loses: its top's line parent is the first node higher
    than that top on the chain ``v, lp[v], lp[lp[v]], ...`` that starts at the edge's
    endpoint ``v`` on the winning side. That chain is the walk along the ridge staying
    as high as possible (each step leaves through the node's own key saddle), and it
    ends at the winning top at the latest, so the loop terminates.

    Returns ``(lp, steps)``: the line parent of every node (-1 for the top of each
    tree) and the total number of chain steps taken (a cost diagnostic).
    """
    n = rank.size
    uf = np.empty(n, ea.dtype)  # the union-find state in the edges' index type (int32: 8 bytes per node less)
    top = np.empty(n, ea.dtype)
    for i in range(n):
        uf[i] = i
        top[i] = i
    lp = np.full(n, -1, np.int64)
    steps = 0
    for e in range(ea.size):
        u = ea[e]
        v = eb[e]
        ru = _find(uf, u)
        rv = _find(uf, v)
        if ru == rv:
            continue
        tu = top[ru]
        tv = top[rv]
        if rank[tu] < rank[tv]:
            lose = tu
            x = v
            win = tv
        else:
            lose = tv
            x = u
            win = tu
        while rank[x] <= rank[lose]:
            x = lp[x]
            steps += 1
        lp[lose] = x
        uf[rv] = ru
        top[ru] = win
    return lp, steps


@njit(cache=True, nogil=True)
def first_ancestor_above(lp, value, tie):
    """For every node, the first node on the chain ``lp[i], lp[lp[i]], ...`` above it in
    the order (``value``, then ``tie``), both larger = above (-1 when the chain ends first)."""
    n = lp.size
    out = np.full(n, -1, np.int64)
    for i in range(n):
        x = lp[i]
        while x >= 0 and not (value[x] > value[i] or (value[x] == value[i] and tie[x] > tie[i])):
            x = lp[x]
        out[i] = x
    return out


@njit(cache=True, nogil=True)
def superlevel_death_areas(g, order, nvalid, row_area):
    """Area of every component of the superlevel filtration of ``g`` when it dies.

    ``order`` lists the flat cells from the highest to the lowest in the total order
    (its first ``nvalid`` entries are the non-NaN cells). Cells join their already
    processed 8-neighbours (union-find); at a cell of value ``v`` that touches several
    components, every component but the one with the highest top dies. The area stored
    at a dying component's top cell is the sum of ``row_area`` over the cells of its
    component of ``{g > v}`` (strictly): a snapshot taken when the component is first
    touched by a cell of value ``v``, before equal-valued cells join anything to it.
    Returns a flat float64 array, NaN except at those tops.
    """
    H, W = g.shape
    n = H * W
    uf = np.full(n, -1, np.int64)
    pos = np.full(n, -1, np.int64)
    area = np.zeros(n)
    snap_lvl = np.full(n, np.nan)
    snap_area = np.zeros(n)
    top = np.arange(n)
    out = np.full(n, np.nan)
    roots = np.empty(8, np.int64)
    gf = g.ravel()
    for k in range(nvalid):
        c = order[k]
        v = gf[c]
        a = row_area[c // W]
        pos[c] = k
        r = c // W
        q = c % W
        nr = 0
        for dr, dc in _NEIGHBOURS_8:
            rr = r + dr
            cc = q + dc
            if rr < 0 or rr >= H or cc < 0 or cc >= W:
                continue
            nb = rr * W + cc
            if uf[nb] < 0:
                continue
            rt = _find(uf, nb)
            seen = False
            for t in range(nr):
                if roots[t] == rt:
                    seen = True
                    break
            if not seen:
                roots[nr] = rt
                nr += 1
                if snap_lvl[rt] != v:
                    snap_lvl[rt] = v
                    snap_area[rt] = area[rt]
        uf[c] = c
        if nr == 0:
            area[c] = a
            snap_lvl[c] = v
            snap_area[c] = 0.0
            continue
        win = roots[0]
        for t in range(1, nr):
            if pos[top[roots[t]]] < pos[top[win]]:
                win = roots[t]
        total = a
        for t in range(nr):
            rt = roots[t]
            if rt != win:
                out[top[rt]] = snap_area[rt]
                uf[rt] = win
            total += area[rt]
        uf[c] = win
        area[win] = total
    return out
