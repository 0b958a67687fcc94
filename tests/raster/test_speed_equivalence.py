"""Speed rewrites of renderer hot paths give the same values as the code they replaced (kept
here as the reference): same seed, same bytes."""
from __future__ import annotations

import heapq

import numpy as np
import pytest
from numba import njit
from scipy import ndimage

from orokit.raster import _kernels
from orokit.raster.enforce import _border_pairs
from orokit.raster.noise import _octave, fractal_noise


def _border_pairs_numpy(owner: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The numpy version replaced by :func:`_kernels.border_pairs`."""
    ny, nx = owner.shape
    ia, ib = [], []
    idx = np.arange(ny * nx, dtype=np.int64).reshape(ny, nx)
    for dr, dc in ((0, 1), (1, -1), (1, 0), (1, 1)):
        a = (slice(0, ny - dr), slice(max(0, -dc), nx - max(0, dc)))
        b = (slice(dr, ny), slice(max(0, dc), nx - max(0, -dc)))
        oa, ob = owner[a], owner[b]
        m = (oa != ob) & (oa >= 0) & (ob >= 0)
        ia.append(idx[a][m])
        ib.append(idx[b][m])
    return np.concatenate(ia), np.concatenate(ib)


@pytest.mark.parametrize("shape", [(1, 1), (1, 7), (7, 1), (2, 2), (13, 17), (40, 33)])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_border_pairs_equal_the_numpy_version(shape, seed):
    owner = np.random.default_rng(seed).integers(-2, 4, shape)
    want = _border_pairs_numpy(owner)
    got = _border_pairs(owner)
    for w, g in zip(want, got):
        assert g.dtype == np.int64 and np.array_equal(w, g)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_basin_owner_equals_the_numpy_version(seed):
    rng = np.random.default_rng(seed)
    tid = rng.integers(-1, 50, 30)
    lab = rng.integers(-1, 30, 1000)
    want = np.where(lab >= 0, tid[np.maximum(lab, 0)], -2)
    assert np.array_equal(_kernels.basin_owner(lab, tid), want)


def _fractal_noise_reference(shape, res, *, amplitude, largest_m=2000.0, persistence=0.55, roughness=None, rng=None):
    """The loop replaced in :func:`fractal_noise` (roughness recomputed per octave)."""
    rng = np.random.default_rng(rng)
    out = np.zeros(shape, np.float32)
    n_oct = max(int(np.floor(np.log2(max(largest_m / (2.0 * res), 1.0)))) + 1, 1)
    amp = 1.0
    for k in range(n_oct):
        wave = largest_m / 2.0**k
        o = _octave(shape, max(wave / res, 1.0), rng) * amp
        if roughness is not None:
            o *= np.power(0.25 + 0.75 * np.clip(roughness, 0.0, 1.0), k / n_oct).astype(np.float32)
        out += o
        amp *= persistence
    peak = float(np.max(np.abs(out))) if out.size else 0.0
    if peak > 0:
        out *= np.float32(amplitude / peak)
    return out


@pytest.mark.parametrize("rough", [None, np.float32, np.float64])
def test_fractal_noise_same_bytes(rough):
    shape = (97, 130)
    r = None
    if rough is not None:
        r = ndimage.gaussian_filter(np.random.default_rng(5).uniform(-0.2, 1.2, shape), 3).astype(rough)
    want = _fractal_noise_reference(shape, 30.0, amplitude=7.0, roughness=r, rng=11)
    got = fractal_noise(shape, 30.0, amplitude=7.0, roughness=r, rng=11)
    assert got.dtype == want.dtype and got.tobytes() == want.tobytes()


def _flood_reference(start, dst, xy, bnd, outlet, base_elevation):
    """The loop replaced by :func:`orokit.raster.rivers._flood_from_outlets` (numpy per edge)."""
    import heapq

    n = xy.shape[0]
    receiver = np.full(n, -1, np.int64)
    flowdist = np.zeros(n)
    seen = np.zeros(n, bool)
    heap = []
    for o in np.flatnonzero(outlet):
        heapq.heappush(heap, (float(min(bnd[o], base_elevation)), 0.0, int(o)))
        seen[o] = True
    order = []
    while heap:
        key, dist, v = heapq.heappop(heap)
        order.append(v)
        for k in range(start[v], start[v + 1]):
            w = int(dst[k])
            if seen[w]:
                continue
            seen[w] = True
            receiver[w] = v
            d = float(np.hypot(*(xy[w] - xy[v])))
            flowdist[w] = dist + d
            heapq.heappush(heap, (max(key, float(bnd[w])), dist + d, w))
    return receiver, flowdist, order


@pytest.mark.parametrize("kind", ["random", "ties", "nan"])
@pytest.mark.parametrize("seed", range(5))
def test_river_flood_equals_the_per_edge_version(seed, kind):
    """The numba flood (and the Python loop it keeps for NaN bounds) gives the per-edge version's
    receivers, distances and order, also with tied bounds and tied edge lengths (a lattice)."""
    from orokit.raster.rivers import _flood_from_outlets

    rng = np.random.default_rng(seed)
    n = 300
    xy = rng.uniform(0, 5000, (n, 2))
    if kind == "ties":
        xy = np.stack(np.meshgrid(np.arange(20.0), np.arange(15.0)), -1).reshape(-1, 2) * 100.0
    e = rng.integers(0, n, (900, 2))
    e = e[e[:, 0] != e[:, 1]]
    bnd = np.where(rng.random(n) < 0.5, rng.uniform(100, 900, n), np.inf)
    if kind == "ties":
        bnd = np.where(np.isfinite(bnd), np.round(bnd, -2), bnd)
    elif kind == "nan":
        bnd[rng.random(n) < 0.1] = np.nan
    outlet = rng.random(n) < 0.05
    src = np.concatenate([e[:, 0], e[:, 1]])
    dst = np.concatenate([e[:, 1], e[:, 0]])
    o = np.argsort(src, kind="stable")
    src, dst = src[o], dst[o]
    start = np.searchsorted(src, np.arange(n + 1))
    want = _flood_reference(start, dst, xy, bnd, outlet, 50.0)
    got = _flood_from_outlets(start, src, dst, xy, bnd, outlet, 50.0)
    assert np.array_equal(got[0], want[0]) and got[1].tobytes() == want[1].tobytes()
    assert np.array_equal(np.asarray(got[2], np.int64), np.asarray(want[2], np.int64))


def test_write_cog_threads_give_the_same_file(tmp_path):
    """write_cog compresses on every core (NUM_THREADS=ALL_CPUS): the file is byte for byte the
    single-threaded one."""
    import rasterio

    from helpers.orometry_oracles import make_dem
    from orokit.io.raster_io import write_cog

    z = ndimage.gaussian_filter(np.random.default_rng(3).normal(0, 50, (700, 900)), 4).astype(np.float32)
    dem = make_dem(z)
    dem.attrs["units"] = "m"
    write_cog(dem, tmp_path / "threads.tif")
    with rasterio.open(tmp_path / "threads.tif") as src:
        profile = {"driver": "COG", "width": src.width, "height": src.height, "count": 1, "dtype": "float32",
                   "crs": src.crs, "transform": src.transform, "nodata": np.nan, "compress": "DEFLATE",
                   "predictor": 3}
        tags, units, desc = src.tags(), src.units, src.descriptions
    with rasterio.open(tmp_path / "one.tif", "w", **profile) as dst:
        dst.write(z, 1)
        dst.units = units
        dst.set_band_description(1, desc[0])
        dst.update_tags(**tags)
    assert (tmp_path / "threads.tif").read_bytes() == (tmp_path / "one.tif").read_bytes()


def _raster_with_ties(shape, seed, nan_share=0.05):
    """Integer heights (many ties, flats) with a few NaN cells."""
    rng = np.random.default_rng(seed)
    z = ndimage.uniform_filter(rng.integers(0, 6, shape).astype(np.float32), 2).round(0)
    z[rng.random(shape) < nan_share] = np.nan
    return np.ascontiguousarray(z, np.float32)


@pytest.mark.parametrize("shape", [(1, 1), (1, 9), (9, 1), (2, 3), (23, 31)])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_ascent_pointers_equal_the_engine(shape, seed):
    """The renderer's pointers of steepest ascent (from the labelling pass) are the engine's (total order,
    ties, NaN), and the labels are those of the engine's labelling without them."""
    from orokit.topology._kernels import ascent_labels, steepest_ascent
    from orokit.topology.engine import steepest_ascent_basins

    z = _raster_with_ties(shape, seed)
    zh = np.pad(z, 1, constant_values=np.nan)
    want, exit_to, _ = steepest_ascent(zh)
    assert (exit_to == -1).all()
    lab, ptr = np.empty(z.size, np.int64), np.full(z.size, -7, np.int64)
    top = ascent_labels(z, lab, ptr)
    assert np.array_equal(ptr, want)
    want_lab, want_top = steepest_ascent_basins(z)
    assert np.array_equal(lab, want_lab) and np.array_equal(top, want_top)


def _same_basins(basins, z, cells, pid):
    """The kept-up-to-date basins give every cell the maximum and owner of a full relabelling."""
    from orokit.raster.enforce import _Basins

    full = _Basins(z, cells, pid)
    assert np.array_equal(basins.own, full.own)
    ok = full.lab >= 0
    assert np.array_equal(basins.lab >= 0, ok)
    assert np.array_equal(basins.top[basins.lab[ok]], full.top[full.lab[ok]])
    assert np.array_equal(basins.ptr, full.ptr)


@pytest.mark.parametrize("seed", range(6))
def test_basins_kept_up_to_date_equal_a_full_relabelling(seed):
    """After random lowerings (single cells, blocks, flats made), :class:`_Basins` equals a fresh one."""
    from orokit.raster.enforce import _Basins

    rng = np.random.default_rng(seed)
    z = _raster_with_ties((37, 29), seed)
    finite = np.flatnonzero(np.isfinite(z.ravel()))
    cells = np.sort(rng.choice(finite, 6, replace=False))
    pid = rng.permutation(6).astype(np.int64)
    basins = _Basins(z, cells, pid)
    zf = z.reshape(-1)
    for _ in range(8):
        if rng.random() < 0.5:
            pick = rng.choice(finite, int(rng.integers(1, 30)))
        else:
            r, c = rng.integers(0, 30), rng.integers(0, 22)
            pick = (np.arange(r, r + 7)[:, None] * z.shape[1] + np.arange(c, c + 7)[None, :]).ravel()
            pick = pick[np.isfinite(zf[pick])]
        before = zf.copy()
        own = basins.own.copy()
        zf[pick] = np.minimum(zf[pick], np.floor(zf[pick] - rng.integers(0, 3, pick.size)))
        moved = basins.update(np.flatnonzero(before.view(np.uint32) != zf.view(np.uint32)))
        _same_basins(basins, z, cells, pid)
        assert np.isin(np.flatnonzero(basins.own != own), moved).all()  # every owner change reported
        # a cut: whole spurious basins (tree peak cells kept out) lowered, some of their cells only
        own = basins.own.copy()
        cut = basins.own == -1
        cut[cells] = False
        hit = np.flatnonzero(cut & (rng.random(zf.size) < 0.7))
        zf[hit] = np.floor(zf[hit] - rng.integers(0, 4, hit.size))
        moved = basins.relabel(np.flatnonzero(cut))
        _same_basins(basins, z, cells, pid)
        assert np.isin(np.flatnonzero(basins.own != own), moved).all() and np.isin(hit, moved).all()


def _full_relabelling(self, changed):
    """The reference for :meth:`_Basins.update`: label the whole raster again (returns the changed
    cells and those whose owner changed)."""
    from orokit.raster.enforce import _Basins

    if not changed.size:
        return np.empty(0, np.int64)
    fresh = _Basins(self.z, self.cells, self.pid)
    moved = np.flatnonzero(fresh.own != self.own)
    self.lab, self.top, self.tid, self.own, self.ptr = fresh.lab, fresh.top, fresh.tid, fresh.own, fresh.ptr
    return np.union1d(np.asarray(changed, np.int64), moved)


@pytest.mark.parametrize("params", [{}, {"keep_hill_ratio": 0.3, "cut_slope": 0.3}])
def test_enforcement_with_basins_kept_up_to_date_same_bytes(monkeypatch, params):
    """A render whose enforcement relabels the whole raster after every change gives the same bytes."""
    from helpers.trees import small_tree
    from orokit.raster.enforce import _Basins
    from orokit.raster.params import RenderParams
    from orokit.raster.render import render_elevation

    p = RenderParams(lam=200.0, **params)
    fast = render_elevation(small_tree(), cell_size_m=25.0, erosion=False, params=p, rng=3).values
    monkeypatch.setattr(_Basins, "update", _full_relabelling)
    monkeypatch.setattr(_Basins, "relabel", _full_relabelling)
    ref = render_elevation(small_tree(), cell_size_m=25.0, erosion=False, params=p, rng=3).values
    assert fast.tobytes() == ref.tobytes()


@njit(cache=True)
def _reconstruct_masked_reference(z: np.ndarray, mask: np.ndarray, step: float, grade: float = 0.0,
                       max_depth: float = 0.0) -> int:
    """The single global flood replaced by :func:`_kernels.reconstruct_masked` (heapq on the whole mask)."""
    ny, nx = z.shape
    heap = [(np.float32(0.0), np.int64(0))]
    heap.pop()
    best = np.full((ny, nx), -np.inf, np.float32)
    base = np.zeros((ny, nx), np.float32)  # the pass (last unlowered height) a cut cell hangs from
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
                    if jj < 0 or jj >= nx or mask[ii, jj]:
                        continue
                    h = z[ii, jj]
                    if np.isfinite(h) and h > best[ii, jj]:
                        best[ii, jj] = h
                        base[ii, jj] = h
                        heapq.heappush(heap, (-h, np.int64(ii * nx + jj)))
    done = ~mask
    count = 0
    while heap:
        negz, v = heapq.heappop(heap)
        i = v // nx
        j = v - i * nx
        zv = -negz
        if mask[i, j]:
            if done[i, j]:
                continue
            done[i, j] = True
            if best[i, j] < z[i, j]:
                z[i, j] = best[i, j]
                count += 1
        elif zv < best[i, j]:
            continue
        bv = base[i, j]
        down = np.float32(step)
        if grade > 0.0 and zv - grade >= bv - max_depth:
            down = np.float32(grade)
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
                if h < zv:
                    cand = h
                    cb = h
                else:
                    cand = zv - down
                    cb = bv
                if cand > best[ii, jj]:
                    best[ii, jj] = cand
                    base[ii, jj] = cb
                    heapq.heappush(heap, (-cand, np.int64(ii * nx + jj)))
    return count


@pytest.mark.parametrize("seed", range(8))
@pytest.mark.parametrize("grade", [0.0, 1.5])
def test_reconstruct_masked_by_components_equals_the_global_flood(seed, grade):
    """The flood per mask component (both cores) gives the bytes and count of one flood of the whole mask."""
    rng = np.random.default_rng(seed)
    z = _raster_with_ties((41, 37), seed, nan_share=0.03) * np.float32(3.0)
    z += rng.integers(0, 2, z.shape).astype(np.float32)  # ties and near-ties
    mask = ndimage.binary_dilation(rng.random(z.shape) < 0.08, iterations=int(rng.integers(1, 4)))
    mask[0, :] |= seed % 2 == 0  # a component along the border
    want, got = z.copy(), z.copy()
    n_want = _reconstruct_masked_reference(want, mask, 1e-3, grade, 2.0)
    n_got = _kernels.reconstruct_masked(got, mask, 1e-3, grade, 2.0)
    assert n_got == n_want and got.tobytes() == want.tobytes()
    assert n_want > 0


@pytest.mark.parametrize("n_lanes", [1, 2, 3, 5])
def test_component_lanes_share_every_component_once_largest_first(n_lanes):
    """Each component goes to one lane; every lane's work is within the largest component of the least."""
    rng = np.random.default_rng(n_lanes)
    sizes = rng.integers(1, 200, 40)
    offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    seed_offsets = np.concatenate([[0], np.cumsum(rng.integers(1, 30, 40))]).astype(np.int64)
    items, lane_offsets = _kernels._component_lanes(offsets, seed_offsets, n_lanes)
    assert np.array_equal(np.sort(items), np.arange(40)) and lane_offsets[-1] == 40
    work = np.diff(offsets) + np.diff(seed_offsets)
    load = np.array([work[items[a:b]].sum() for a, b in zip(lane_offsets[:-1], lane_offsets[1:])])
    assert load.max() - load.min() <= work.max()
    for a, b in zip(lane_offsets[:-1], lane_offsets[1:]):
        assert np.all(np.diff(work[items[a:b]]) <= 0)  # largest first within each lane


@pytest.mark.parametrize("seed", range(4))
def test_mask_components_are_scipy_labels(seed):
    rng = np.random.default_rng(seed + 3)
    mask = rng.random((50, 60)) < 0.4
    z = rng.random(mask.shape).astype(np.float32)
    z[rng.random(mask.shape) < 0.05] = np.nan
    comp, cells, offsets, seeds, seed_offsets = _kernels.mask_components(mask, z)
    lab, n = ndimage.label(mask, structure=np.ones((3, 3)))
    assert offsets.size - 1 == n and cells.size == mask.sum() and seed_offsets.size == n + 1
    # same partition; numbered in raster order of the first cell (as scipy does)
    assert np.array_equal(comp + 1, lab)
    for k in range(n):
        assert (comp.reshape(-1)[cells[offsets[k]:offsets[k + 1]]] == k).all()
        # the seeds: the unmasked finite cells 8-adjacent to the component, each once (the flood's former np.unique)
        near = ndimage.binary_dilation(lab == k + 1, structure=np.ones((3, 3))) & ~mask & np.isfinite(z)
        got = seeds[seed_offsets[k]:seed_offsets[k + 1]]
        assert got.size == np.unique(got).size
        assert np.array_equal(np.sort(got), np.flatnonzero(near))


@pytest.mark.parametrize("res", [30.0, 92.6, 0.7, 1.0 / 3.0])
@pytest.mark.parametrize("share", [0.0005, 0.02, 0.5, 1.0])
def test_node_distance_equals_scipy_edt(res, share):
    """The renderer's distance to peaks and saddles has the bytes of ``distance_transform_edt(...).astype(float32)``."""
    from orokit.raster.render import _node_distance

    mask = np.random.default_rng(int(share * 1e4)).random((61, 47)) >= share
    mask[0, 0] = False  # at least one feature
    want = ndimage.distance_transform_edt(mask, sampling=res).astype(np.float32)
    got = _node_distance(mask, res)
    assert got.dtype == np.float32 and got.tobytes() == want.tobytes()


@pytest.mark.parametrize("seed", range(4))
def test_pass_violations_equal_the_numpy_version(seed):
    """One pass with a table of bottlenecks gives the border pairs above their bottleneck of the
    numpy version it replaced (border pairs, np.unique of the owner pairs, bottlenecks, filter)."""
    rng = np.random.default_rng(seed)
    n = 30
    own = rng.integers(-2, n, (50, 40))
    own[rng.random(own.shape) < 0.5] = rng.integers(0, 3)  # large basins and ties of owners
    z = (rng.random((50, 40)) * 100).astype(np.float32)
    m = n - 1 - seed  # with seed > 0, peaks without an edge: separate trees (-inf bottlenecks)
    parent, height, depth = _kernels.merge_tree(n, np.arange(m), np.arange(1, m + 1), rng.random(m) * 50)
    ia, ib, bn, total = _kernels.pass_violations(own, z, parent, height, depth, n, 1e-3)
    ra, rb = _border_pairs(own)
    o = own.reshape(-1)
    lo, hi = np.minimum(o[ra], o[rb]), np.maximum(o[ra], o[rb])
    keys, inv = np.unique(lo * n + hi, return_inverse=True)
    b = _kernels.bottlenecks(parent, height, depth, keys // n, keys % n)[inv.ravel()]
    za, zb = z.reshape(-1)[ra].astype(np.float64), z.reshape(-1)[rb].astype(np.float64)
    viol = (np.minimum(za, zb) > b + 1e-3) & np.isfinite(b)
    assert total == ra.size and viol.any()
    assert np.array_equal(ia, ra[viol]) and np.array_equal(ib, rb[viol]) and np.array_equal(bn, b[viol])


def _sample_elevation_reference(points, ridge_xy, ridge_z, river_xy, river_z, river_w, ridge_slope, ridge_floor,
                                k_neighbours, floor_slope=0.05):
    """The version replaced in :func:`sample_elevation`: a nearest-ridge search, then a separate
    k-nearest search inside :func:`flank_envelope` (linear profile, floor_relief_ratio 0)."""
    from scipy.spatial import cKDTree

    from orokit.raster.interpolate import flank_envelope

    tree = cKDTree(ridge_xy)
    dT, iq = tree.query(points, workers=-1)
    dR, ir = cKDTree(river_xy).query(points, workers=-1)
    w = river_w[ir]
    hq, hr = ridge_z[iq], river_z[ir]
    denom = np.maximum(dR + dT - w, 1e-9)
    alpha = np.clip(dT / denom, 0.0, 1.0)
    h = np.where(dR < w, hr, (1.0 - alpha) * hq + alpha * hr)
    env = flank_envelope(points, ridge_xy, ridge_z, ridge_slope, ridge_floor=ridge_floor,
                         k_neighbours=k_neighbours, tree=tree)
    floor = np.minimum(hr + floor_slope * np.maximum(dR - w, 0.0), h)
    return np.maximum(np.minimum(h, env), floor), dT, dR


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("k", [1, 3, 16])
def test_sample_elevation_one_search_equals_two(seed, k):
    """The nearest ridge point taken from the cones' k-nearest search (the single-nearest search
    only where the nearest two are equally far) gives the same bytes as the two searches,
    also on a lattice of ridge points where many samples are equally far from two of them."""
    from scipy.spatial import cKDTree

    from orokit.raster.interpolate import sample_elevation

    rng = np.random.default_rng(seed)
    if seed % 2:  # ties: samples on the lattice's cell centres and edges
        g = np.arange(0.0, 1000.0, 100.0)
        ridge_xy = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
        pts = np.concatenate([ridge_xy + 50.0, ridge_xy + [50.0, 0.0], rng.uniform(0, 1000, (200, 2))])
    else:
        ridge_xy = rng.uniform(0, 1000, (120, 2))
        pts = rng.uniform(-100, 1100, (500, 2))
    n = ridge_xy.shape[0]
    ridge_z = rng.uniform(100, 900, n)
    slope, floor = rng.uniform(0.2, 1.0, n), ridge_z - rng.uniform(50, 400, n)
    river_xy = rng.uniform(0, 1000, (60, 2))
    river_z, river_w = rng.uniform(0, 100, 60), rng.uniform(0, 40, 60)
    want = _sample_elevation_reference(pts, ridge_xy, ridge_z, river_xy, river_z, river_w, slope, floor, k)
    for tree in (None, cKDTree(ridge_xy)):
        got = sample_elevation(pts, ridge_xy, ridge_z, river_xy, river_z, river_w, ridge_slope=slope,
                               ridge_floor=floor, k_neighbours=k, tree=tree)
        for g_, w_ in zip(got, want):
            assert g_.tobytes() == w_.tobytes()


def test_poisson_samples_same_points_on_another_thread():
    """The darts released from the GIL on a second thread (as ``build_skeleton`` throws them) give
    the same points as on the calling thread, and leave the caller's generator in the same state."""
    from concurrent.futures import ThreadPoolExecutor

    from orokit.raster.interpolate import poisson_samples

    ext = (0.0, 0.0, 3000.0, 2000.0)
    rng_a, rng_b = np.random.default_rng(3), np.random.default_rng(3)
    want = poisson_samples(ext, 90.0, rng=rng_a)
    with ThreadPoolExecutor(2) as pool:
        got = pool.submit(poisson_samples, ext, 90.0, rng=rng_b).result()
        again = pool.submit(poisson_samples, ext, 90.0, rng=np.random.default_rng(3)).result()
    assert want.shape[0] > 100 and got.tobytes() == want.tobytes() == again.tobytes()
    assert rng_a.random() == rng_b.random()


class _InlineExecutor:
    """A ``ThreadPoolExecutor`` stand-in that runs each job at once on the calling thread."""

    def __init__(self, *args, **kwargs):
        pass

    def submit(self, fn, /, *args, **kwargs):
        from concurrent.futures import Future

        fut: Future = Future()
        fut.set_result(fn(*args, **kwargs))
        return fut

    def shutdown(self, wait=True):
        pass


@pytest.mark.parametrize("params", [{}, {"detail_replace": False}, {"detail_gain": 0.0, "noise_ratio": 0.3},
                                    {"smooth_m": 60.0}])
def test_render_jobs_on_threads_same_bytes(monkeypatch, params):
    """The darts, the detail's law and noise on second threads give the bytes and the recorded parameters
    of the same jobs run in line (the skeleton too: same samples, rivers and TIN)."""
    from helpers.trees import small_tree
    from orokit.raster import render, skeleton
    from orokit.raster.params import RenderParams

    p = RenderParams(lam=200.0, **params)
    fast, fs = render.render_elevation(small_tree(), cell_size_m=25.0, erosion=False, params=p, rng=5,
                                       return_skeleton=True)
    monkeypatch.setattr(render, "ThreadPoolExecutor", _InlineExecutor)
    monkeypatch.setattr(skeleton, "ThreadPoolExecutor", _InlineExecutor)
    ref, rs = render.render_elevation(small_tree(), cell_size_m=25.0, erosion=False, params=p, rng=5,
                                      return_skeleton=True)
    assert fast.values.tobytes() == ref.values.tobytes()
    assert fast.attrs["parameters"] == ref.attrs["parameters"]
    assert fs.tin.xy.tobytes() == rs.tin.xy.tobytes() and fs.tin.z.tobytes() == rs.tin.z.tobytes()


@pytest.mark.parametrize("seed", range(3))
def test_pass_violations_on_two_threads_equal_one_call(seed):
    """The directions split over two threads and concatenated give the arrays of one call."""
    from orokit.raster.enforce import _pass_violations

    rng = np.random.default_rng(seed)
    n = 40
    own = rng.integers(-2, n, (70, 55))
    own[rng.random(own.shape) < 0.4] = rng.integers(0, 3)
    z = (rng.random((70, 55)) * 100).astype(np.float32)
    parent, height, depth = _kernels.merge_tree(n, np.arange(n - 1), np.arange(1, n), rng.random(n - 1) * 50)
    ia, ib, bn, _ = _kernels.pass_violations(own, z, parent, height, depth, n, 1e-3)
    got = _pass_violations(own, z, parent, height, depth, n, 1e-3)
    assert ia.size > 10
    for g, w in zip(got, (ia, ib, bn)):
        assert g.dtype == w.dtype and g.tobytes() == w.tobytes()


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("kept_share", [0.0, 0.3])
def test_cut_mask_equals_the_explicit_mask_and_the_flood_leaves_its_mask(seed, kept_share):
    """The enforcement's cut mask (the spurious basins themselves when none is kept) equals the explicit
    ``sp & ~keep[lab]``; the flood that cuts them never writes its mask (so the mask may be ``sp`` itself)."""
    from orokit.raster.enforce import _cut_mask

    rng = np.random.default_rng(seed)
    lab = rng.integers(-1, 60, (33, 29)).reshape(-1)
    sp = rng.random((33, 29)) < 0.5
    keep = rng.random(60) < kept_share
    got = _cut_mask(sp, keep, lab)
    assert got.dtype == bool and np.array_equal(got, sp & ~keep[np.maximum(lab, 0)].reshape(sp.shape))
    z = _raster_with_ties((33, 29), seed, nan_share=0.03)
    before = got.copy()
    _kernels.reconstruct_masked(z, got, 1e-3, 0.5, 2.0)
    assert np.array_equal(got, before)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("zeros", [False, True])
def test_unique_points_equal_numpy_unique_rows(seed, zeros):
    """The TIN's duplicate merge gives np.unique(xy, axis=0)'s points, order and inverse (with points on
    the axes, +0.0 and -0.0 among them, and exact duplicates)."""
    from orokit.raster.tin import unique_points

    rng = np.random.default_rng(seed)
    xy = np.round(rng.random((3000, 2)) * 50.0, 1) - 25.0  # many exact duplicates, ties in x with other y
    if zeros:
        xy[rng.integers(0, 3000, 40), rng.integers(0, 2, 40)] = 0.0
        xy[rng.integers(0, 3000, 40), rng.integers(0, 2, 40)] = -0.0
    want_u, want_i = np.unique(xy, axis=0, return_inverse=True)
    got_u, got_i = unique_points(xy)
    assert got_u.tobytes() == want_u.tobytes() and np.array_equal(got_i, want_i.ravel())
    assert np.array_equal(got_u[got_i], xy)


@pytest.mark.parametrize("shape", [(1, 9), (9, 1), (2, 2), (6, 2), (2, 7), (31, 26)])
@pytest.mark.parametrize("seed", range(4))
def test_pass_violations_near_changed_cells_equal_a_full_check(shape, seed):
    """After owners and elevations change at some cells (edges and corners among them, runs of
    neighbours, repeats), checking again only the pairs at those cells gives the arrays of a full check."""
    rng = np.random.default_rng(seed)
    n = 12
    own = rng.integers(-2, n, shape)
    own[rng.random(shape) < 0.4] = rng.integers(0, 3)
    z = (rng.random(shape) * 100).astype(np.float32)
    m = n - 1 - seed % 2  # with an odd seed, a peak without an edge (-inf bottlenecks)
    parent, height, depth = _kernels.merge_tree(n, np.arange(m), np.arange(1, m + 1), rng.random(m) * 50)
    ia, ib, bn, _ = _kernels.pass_violations(own, z, parent, height, depth, n, 1e-3)
    size = own.size
    for _ in range(6):
        k = int(rng.integers(0, max(size // 3, 1) + 1))
        cells = rng.choice(size, k)  # with repeats
        if rng.random() < 0.5 and size > 4:
            start = int(rng.integers(0, size - 3))
            cells = np.concatenate([cells, np.arange(start, start + 3)])  # neighbours changed together
        cells = cells.astype(np.int64)
        o, zf = own.reshape(-1), z.reshape(-1)
        o[cells] = np.where(rng.random(cells.size) < 0.5, rng.integers(-2, n, cells.size), o[cells])
        zf[cells] = np.where(rng.random(cells.size) < 0.5, (rng.random(cells.size) * 100).astype(np.float32),
                             zf[cells])
        ia, ib, bn = _kernels.pass_violations_near(own, z, parent, height, depth, 1e-3, cells, ia, ib, bn)
        wa, wb, wv, _ = _kernels.pass_violations(own, z, parent, height, depth, n, 1e-3)
        for g, w in zip((ia, ib, bn), (wa, wb, wv)):
            assert g.dtype == w.dtype and g.tobytes() == w.tobytes()


@pytest.mark.parametrize("params", [{}, {"keep_hill_ratio": 0.3, "cut_slope": 0.3}])
def test_enforcement_with_incremental_pass_checks_same_bytes(monkeypatch, params):
    """A render whose enforcement checks every border pair in every round finds the same pairs in every
    round and gives the same bytes (the incremental check is used: more than one round on this tree)."""
    from helpers.trees import small_tree
    from orokit.raster import enforce
    from orokit.raster.params import RenderParams
    from orokit.raster.render import render_elevation

    p = RenderParams(lam=200.0, **params)
    found: list[list[tuple[bytes, ...]]] = [[], []]
    whole, near = enforce._pass_violations, _kernels.pass_violations_near

    def logged(run, f):
        def call(*args):
            out = f(*args)
            found[run].append(tuple(a.tobytes() for a in out))
            return out
        return call

    def full(owner, z, parent, height, depth, tol, cells, ia, ib, bn):
        # any n above every owner keys the owner pairs uniquely (the merge tree has >= n nodes)
        return _kernels.pass_violations(owner, z, parent, height, depth, parent.size, tol)[:3]

    monkeypatch.setattr(enforce, "_pass_violations", logged(0, whole))
    monkeypatch.setattr(_kernels, "pass_violations_near", logged(0, near))
    fast = render_elevation(small_tree(), cell_size_m=25.0, erosion=False, params=p, rng=3).values
    monkeypatch.setattr(enforce, "_pass_violations", logged(1, whole))
    monkeypatch.setattr(_kernels, "pass_violations_near", logged(1, full))
    ref = render_elevation(small_tree(), cell_size_m=25.0, erosion=False, params=p, rng=3).values
    assert fast.tobytes() == ref.tobytes()
    assert found[0] == found[1] and len(found[0]) > 1


def _detail_slope_numpy(z, res, smooth_m, power, flat_deg):
    """The numpy/scipy version of :func:`orokit.raster.render._detail_slope` that the slope and flat-test
    kernels replaced."""
    gy, gx = np.gradient(np.asarray(z, np.float32), np.float32(res))
    s = np.hypot(gx, gy)
    flat = None
    if flat_deg > 0:
        t = np.float32(np.tan(np.radians(flat_deg)))
        flat = np.clip((ndimage.minimum_filter(s, size=3, mode="nearest") - t) / t, 0.0, 1.0)
    if power == 0:
        return flat, None
    w = ndimage.gaussian_filter(s, max(0.5 * smooth_m / res, 0.5), mode="nearest")
    if power != 1:
        w **= np.float32(power)
    m = float(np.sqrt(np.mean(w * w, dtype=np.float64)))
    return flat, (w * np.float32(1.0 / m) if m > 0 else np.ones(z.shape, np.float32))


@pytest.mark.parametrize("shape", [(2, 2), (2, 9), (9, 2), (3, 3), (57, 43)])
@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("res", [30.0, 12.7, 0.3])
def test_detail_slope_kernels_equal_numpy(shape, seed, res):
    """The slope magnitude and flat test in numba give numpy's and scipy's float32 bytes (flats and
    ties, slopes around the flat threshold, steep cliffs, negative heights, float64 input)."""
    from orokit.raster.render import _detail_slope

    rng = np.random.default_rng(seed)
    t = np.tan(np.radians(2.0)) * res
    z = (rng.integers(-2, 3, shape) * t * rng.choice([0.5, 1.0, 1.5, 40.0], shape)).astype(np.float32)
    z += (rng.random(shape) * (res if seed == 2 else 0.0)).astype(np.float32) - np.float32(500.0 * seed)
    for zz, flat_deg, power in ((z, 2.0, 1.0), (z.astype(np.float64), 3.0, 0.7), (z, 0.0, 0.0), (z, 2.0, 0.0)):
        got = _detail_slope(zz, res, 200.0, power, flat_deg)
        want = _detail_slope_numpy(zz, res, 200.0, power, flat_deg)
        for g, w in zip(got, want):
            assert (g is None) == (w is None)
            if w is not None:
                assert g.dtype == w.dtype and g.tobytes() == w.tobytes()
    ramp = _detail_slope(z, res, 200.0, 1.0, 2.0)[0]
    if shape == (57, 43):  # flat cells, cells on the ramp and steep ones
        assert ramp is not None and (ramp == 0).any() and ((ramp > 0) & (ramp < 1)).any() and (ramp == 1).any()


def test_detail_slope_too_small_raises_numpys_error():
    from orokit.raster.render import _detail_slope

    with pytest.raises(ValueError, match="too small"):
        _detail_slope(np.zeros((1, 5), np.float32), 30.0, 200.0, 1.0, 2.0)


@pytest.mark.parametrize("shape", [(1, 1), (1, 30), (30, 1), (5, 4), (64, 77)])
@pytest.mark.parametrize("sigma", [0.5, 1.7, 3.3333333333333335, 9.0])
@pytest.mark.parametrize("seed", range(2))
def test_gaussian_kernel_equals_scipy(shape, sigma, seed):
    """The numba Gaussian gives scipy.ndimage.gaussian_filter's float32 bytes (mode nearest; radius larger
    than the grid among them; smooth and rough inputs, large offsets)."""
    from orokit.raster.render import _gaussian_weights

    rng = np.random.default_rng(seed)
    s = (rng.random(shape) * 10.0 ** rng.uniform(-3, 3, shape)).astype(np.float32)
    s += np.float32(1000.0 * seed)
    want = ndimage.gaussian_filter(s, sigma, mode="nearest")
    got = _kernels.gaussian_nearest(s, _gaussian_weights(sigma))
    assert got.dtype == want.dtype and got.tobytes() == want.tobytes()


def test_rivers_search_the_tree_relief_once_same_bytes(monkeypatch):
    """The rivers' base cap and floor share one search of the tree's relief at the river nodes (each set of
    points and k searched once), and the render is the one whose floor searches for itself."""
    from helpers.trees import small_tree
    from orokit.raster import render, rivers, skeleton
    from orokit.raster.params import RenderParams

    calls: list[tuple[np.ndarray, int]] = []
    search = rivers.local_relief

    def counting(xy, peak_xyz, saddle_xyz, *, k=16):
        calls.append((np.array(xy, float), int(k)))
        return search(xy, peak_xyz, saddle_xyz, k=k)

    p = RenderParams(lam=200.0)
    assert p.saddle_floor_ratio is not None and p.river_base_saddle_k == p.saddle_floor_k
    monkeypatch.setattr(skeleton, "local_relief", counting)
    monkeypatch.setattr(rivers, "local_relief", counting)  # saddle_floor's own search
    shared = render.render_elevation(small_tree(), cell_size_m=25.0, erosion=False, params=p, rng=5)
    assert len(calls) >= 2
    for i in range(len(calls)):
        for j in range(i + 1, len(calls)):
            assert not (calls[i][1] == calls[j][1] and np.array_equal(calls[i][0], calls[j][0]))

    floor = rivers.saddle_floor

    def own_search(xy, peak_xyz, saddle_xyz, *, relief=None, **kw):
        return floor(xy, peak_xyz, saddle_xyz, **kw)

    monkeypatch.setattr(skeleton, "saddle_floor", own_search)
    ref = render.render_elevation(small_tree(), cell_size_m=25.0, erosion=False, params=p, rng=5)
    assert shared.values.tobytes() == ref.values.tobytes()


@njit(cache=True)
def _rasterize_triangles_reference(vx, vy, vz, tri, x0, y0, res, ny, nx):
    """The one-pass scan conversion replaced by :func:`_kernels.rasterize_triangles` (row bands on threads)."""
    out = np.full((ny, nx), np.nan, np.float32)
    tol = -1e-9
    for t in range(tri.shape[0]):
        a, b, c = tri[t, 0], tri[t, 1], tri[t, 2]
        ax, ay, az = vx[a], vy[a], vz[a]
        bx, by, bz = vx[b], vy[b], vz[b]
        cx, cy, cz = vx[c], vy[c], vz[c]
        det = (by - cy) * (ax - cx) + (cx - bx) * (ay - cy)
        if det == 0.0:
            continue
        jmin = max(int(np.floor((min(ax, bx, cx) - x0) / res - 0.5)), 0)
        jmax = min(int(np.ceil((max(ax, bx, cx) - x0) / res - 0.5)), nx - 1)
        imin = max(int(np.floor((y0 - max(ay, by, cy)) / res - 0.5)), 0)
        imax = min(int(np.ceil((y0 - min(ay, by, cy)) / res - 0.5)), ny - 1)
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


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("shape", [(1, 1), (1, 9), (7, 1), (40, 33), (97, 61)])
def test_rasterize_triangles_in_row_bands_equals_one_pass(seed, shape):
    """Row bands on threads give every cell the value of one pass over the triangles in order, also on the
    edges two triangles share (vertices on cell centres), with degenerate and overlapping triangles, and
    cells outside every triangle NaN."""
    from scipy.spatial import Delaunay

    rng = np.random.default_rng(seed)
    ny, nx = shape
    res, x0, y0 = 10.0, 100.0, 5000.0
    n = 40 + 10 * seed
    # half the vertices on cell centres (edges through centres: the shared-edge cells), some outside the grid
    xy = np.column_stack([x0 + rng.uniform(-20.0, nx * res + 20.0, n), y0 - rng.uniform(-20.0, ny * res + 20.0, n)])
    on = rng.random(n) < 0.5
    xy[on, 0] = x0 + (np.floor((xy[on, 0] - x0) / res) + 0.5) * res
    xy[on, 1] = y0 - (np.floor((y0 - xy[on, 1]) / res) + 0.5) * res
    xy = np.unique(xy, axis=0)
    tri = Delaunay(xy).simplices.astype(np.int64)
    vz = rng.normal(0.0, 100.0, xy.shape[0])
    # a degenerate triangle, and copies of some triangles on their own vertices at other heights, first and
    # last (overlaps: the last triangle over a cell wins)
    m = xy.shape[0]
    first, last = tri[:4], tri[4:8]
    xy = np.concatenate([xy, xy[first.ravel()], xy[last.ravel()]])
    vz = np.concatenate([vz, rng.normal(500.0, 100.0, first.size + last.size)])
    own = m + np.arange(first.size + last.size, dtype=np.int64).reshape(-1, 3)
    tri = np.concatenate([own[:first.shape[0]], tri, [[0, 0, 1]], own[first.shape[0]:]])
    args = (np.ascontiguousarray(xy[:, 0]), np.ascontiguousarray(xy[:, 1]), vz, tri, x0, y0, res, ny, nx)
    got = _kernels.rasterize_triangles(*args)
    want = _rasterize_triangles_reference(*args)
    assert got.tobytes() == want.tobytes()
    assert np.isfinite(want).any() or min(shape) == 1
