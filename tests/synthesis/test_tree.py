"""Divide Tree synthesis: validity, orometry, controls, reproducibility, bad input."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from orokit.errors import CRSError, InputError
from orokit.synthesis.orometry import nearest_higher_peak, tree_orometry
from orokit.synthesis.tree import SynthesisParams, peaks_table, synthesize_divide_tree

SIZE = 25_000.0  # ~ 150 peaks at the test type's density: fast


@pytest.fixture(scope="module")
def tree(small_type):
    return synthesize_divide_tree(small_type, size_m=SIZE, rng=7)


def _components(tree) -> int:
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    a, b = tree.edges["peak_a"].to_numpy(), tree.edges["peak_b"].to_numpy()
    g = coo_matrix((np.ones(a.size), (a, b)), shape=(tree.n_peaks, tree.n_peaks))
    return connected_components(g, directed=False)[0]


def test_tree_is_valid_connected_and_acyclic(tree, small_type):
    tree.validate()
    assert tree.n_peaks == round(small_type.peak_density_per_km2 * SIZE**2 / 1e6)
    assert len(tree.edges) == tree.n_peaks - 1 == tree.n_saddles
    assert _components(tree) == 1
    assert tree.edges["saddle"].is_unique
    pz = tree.peaks["elevation"].to_numpy()
    sz = tree.saddles["elevation"].to_numpy()[tree.edges["saddle"].to_numpy()]
    assert np.all(sz <= np.minimum(pz[tree.edges["peak_a"]], pz[tree.edges["peak_b"]]))
    assert np.all(sz >= 0)


def test_every_peak_keeps_min_prominence(tree, small_type):
    table = tree.prominence_table()
    nonroot = table["key_saddle"] >= 0
    assert (table.loc[nonroot, "prominence"] >= small_type.min_prominence_m - 1e-9).all()
    assert (~nonroot).sum() == 1
    assert tree.attrs["peaks_below_eps"] == 0


def _oracle_orometry(tree):
    """Brute force over the tree graph, independent of DivideTree.prominence_table.

    For each peak i: walk the (unique) tree path to every other peak j, keeping the
    lowest saddle met; the key-saddle height of i is the highest such bottleneck over
    the peaks j higher than i (ties: the lower id is higher), its key saddle the saddle
    that realises it, and the parent the highest peak on the far side of that saddle.
    """
    z = tree.peaks["elevation"].to_numpy(float)
    sz = tree.saddles["elevation"].to_numpy(float)
    n = z.size
    adj = [[] for _ in range(n)]
    for a, b, s in tree.edges[["peak_a", "peak_b", "saddle"]].itertuples(index=False):
        adj[a].append((b, s))
        adj[b].append((a, s))

    def higher(j, i):
        return z[j] > z[i] or (z[j] == z[i] and j < i)

    prom, key_h, parent, key_unique = np.full(n, np.nan), np.full(n, np.nan), np.full(n, -1), np.ones(n, bool)
    for i in range(n):
        # bottleneck (lowest saddle) and the saddle realising it on the path i -> j, by DFS
        low = {i: (np.inf, -1)}
        stack = [i]
        while stack:
            u = stack.pop()
            for v, s in adj[u]:
                if v not in low:
                    low[v] = min(low[u], (sz[s], s))
                    stack.append(v)
        cands = [(low[j][0], low[j][1]) for j in range(n) if j != i and higher(j, i)]
        if not cands:
            prom[i] = z[i]
            continue
        best = max(c[0] for c in cands)
        keys = {c[1] for c in cands if c[0] == best}
        key_unique[i] = len(keys) == 1 and np.sum(sz == best) == 1
        key = min(keys)
        key_h[i], prom[i] = best, z[i] - best
        # parent: highest peak of the far side of the key saddle, connected through higher saddles
        # (what the elder-rule merge at that saddle sees); the far endpoint is the one i cannot
        # reach without crossing the key saddle
        a, b = (int(v) for v in tree.edges.loc[tree.edges["saddle"] == key, ["peak_a", "peak_b"]].iloc[0])
        near = _component(adj, i, lambda s: s != key)
        start = b if a in near else a
        far = _component(adj, start, lambda s: sz[s] > best)
        parent[i] = max(far, key=lambda j: (z[j], -j))
    return prom, key_h, parent, key_unique


def _component(adj, start, usable):
    seen = {start}
    stack = [start]
    while stack:
        u = stack.pop()
        for v, s in adj[u]:
            if v not in seen and usable(s):
                seen.add(v)
                stack.append(v)
    return seen


def test_peaks_table_matches_brute_force_oracle(tree):
    """peaks_table (via the OT state and prominence_table) against a brute-force oracle (review T1)."""
    pt = peaks_table(tree)
    prom, key_h, parent, unique = _oracle_orometry(tree)
    assert np.allclose(pt["prominence"].to_numpy(), prom)
    keyed = np.isfinite(key_h)
    assert np.allclose(pt["saddle_elevation"].to_numpy()[keyed], key_h[keyed])
    assert np.isnan(pt["saddle_elevation"].to_numpy()[~keyed]).all()
    assert unique.sum() > 0.9 * tree.n_peaks
    assert (pt["island_parent"].to_numpy()[unique] == parent[unique]).all()
    z = tree.peaks["elevation"].to_numpy(float)
    assert np.allclose(pt["dominance"].to_numpy(), prom / z)
    # every peak keeps the eps the synthesis enforced, judged by the oracle
    assert (prom[keyed] >= tree.attrs["min_prominence_m"] - 1e-9).all()
    expected = ["row", "col", "x", "y", "lon", "lat", "elevation", "prominence", "saddle_row", "saddle_col",
                "saddle_x", "saddle_y", "saddle_elevation", "island_parent", "island_parent_row", "island_parent_col",
                "line_parent", "line_parent_row", "line_parent_col",
                "prominence_parent", "prominence_parent_row", "prominence_parent_col", "dominance",
                "isolation", "isolation_row", "isolation_col", "isolation_x", "isolation_y", "prominence_exact",
                "isolation_exact", "geometry"]
    assert [c for c in expected if c not in pt.columns] == []
    assert pt.index.name == "peak_id"
    root = int(np.argmax(pt["elevation"]))
    assert pt["island_parent"].iloc[root] == -1 and np.isnan(pt["saddle_x"].iloc[root])
    assert np.isnan(pt["isolation"].iloc[root])


def test_isolation_is_nearest_higher_peak_brute_force(tree):
    x, y, z = (tree.peaks[c].to_numpy() for c in ("x", "y", "elevation"))
    got = nearest_higher_peak(x, y, z)
    for i in range(0, x.size, 7):
        higher = np.flatnonzero((z > z[i]) | ((z == z[i]) & (np.arange(z.size) < i)))
        if higher.size == 0:
            assert got[i] == -1
            continue
        d = np.hypot(x[higher] - x[i], y[higher] - y[i])
        assert np.hypot(x[got[i]] - x[i], y[got[i]] - y[i]) == pytest.approx(d.min())


def test_same_seed_same_tree_other_seed_other_tree(small_type, tree):
    again = synthesize_divide_tree(small_type, size_m=SIZE, rng=7)
    assert again.equals(tree)
    other = synthesize_divide_tree(small_type, size_m=SIZE, rng=8)
    assert not other.equals(tree)


def test_given_peak_count_and_paper_mode(small_type):
    t = synthesize_divide_tree(small_type, size_m=SIZE, n_peaks=60, params=SynthesisParams(saddle_placement="paper"), rng=1)
    t.validate()
    assert t.n_peaks == 60


def test_density_control_zero_means_no_peaks(small_type):
    cp = np.ones((32, 32))
    cp[:, :16] = 0.0  # west half is sea
    t = synthesize_divide_tree(small_type, size_m=SIZE, control_density=cp, rng=3)
    x = t.peaks["x"].to_numpy()
    # bilinear resampling blurs the coast by at most one source cell
    assert (x >= SIZE / 2 - SIZE / 32).all()
    assert (x >= SIZE / 2).mean() > 0.95
    # the count follows the land area (plus the blurred coast strip)
    assert t.n_peaks == pytest.approx(small_type.peak_density_per_km2 * SIZE**2 / 2e6, rel=0.06)


def test_elevation_control_is_honoured(small_type):
    lo, hi = small_type.histograms["elevation"].edges[0], small_type.histograms["elevation"].edges[-1]
    ch = np.tile(np.linspace(lo, hi, 64), (64, 1))  # rising eastwards
    t = synthesize_divide_tree(small_type, size_m=SIZE, control_elevation=ch, rng=5)
    x, z = t.peaks["x"].to_numpy(), t.peaks["elevation"].to_numpy()
    assert np.corrcoef(x, z)[0, 1] > 0.6
    free = synthesize_divide_tree(small_type, size_m=SIZE, params=SynthesisParams(auto_elevation_m=None), rng=5)
    assert abs(np.corrcoef(free.peaks["x"], free.peaks["elevation"])[0, 1]) < 0.4


def test_fixed_peaks_are_kept(small_type):
    fixed = pd.DataFrame({"x": [5000.0, 20000.0], "y": [5000.0, 12000.0], "elevation": [2600.0, 1500.0]})
    t = synthesize_divide_tree(small_type, size_m=SIZE, fixed_peaks=fixed, rng=2)
    t.validate()
    for _, row in fixed.iterrows():
        d = np.hypot(t.peaks["x"] - row.x, t.peaks["y"] - row.y)
        i = int(np.argmin(d))
        assert d.iloc[i] < 1e-6 and t.peaks["elevation"].iloc[i] == row.elevation and t.peaks["fixed"].iloc[i]


def test_too_many_fixed_peaks(small_type):
    n = 400
    fixed = pd.DataFrame({"x": np.linspace(10, 990, n), "y": np.full(n, 500.0), "elevation": np.full(n, 900.0)})
    with pytest.raises(InputError, match="fixed peaks but the domain holds only"):
        synthesize_divide_tree(small_type, size_m=1000.0, fixed_peaks=fixed, rng=0)


def test_fixed_peak_outside_domain(small_type):
    with pytest.raises(InputError, match="outside the domain"):
        synthesize_divide_tree(small_type, size_m=SIZE, fixed_peaks=np.array([[-10.0, 5.0, 900.0]]), rng=0)


def test_domain_too_small(small_type):
    with pytest.raises(InputError, match="too few"):
        synthesize_divide_tree(small_type, size_m=500.0, rng=0)


def test_control_raster_outside_domain(small_type, make_dem):
    far = make_dem(np.ones((16, 16)), res=100.0, crs="EPSG:32633", origin=(900_000.0, 8_000_000.0))
    with pytest.raises(InputError, match="does not overlap"):
        synthesize_divide_tree(small_type, size_m=SIZE, crs="EPSG:32633", center=(15.0, 45.0),
                               control_density=far, rng=0)


def test_control_raster_in_other_crs_is_reprojected(small_type, make_dem):
    # a geographic raster covering the domain: density 0 in its western half
    arr = np.ones((40, 40))
    arr[:, :20] = 0.0
    cp = make_dem(arr, res=0.01, crs="EPSG:4326", origin=(14.8, 45.2))
    t = synthesize_divide_tree(small_type, size_m=SIZE, crs="EPSG:32633", center=(15.0, 45.0),
                               control_density=cp, rng=0)
    lon = peaks_table(t)["lon"].to_numpy()
    assert (lon >= 15.0 - 0.005).all()


def test_geographic_output_crs_is_refused(small_type):
    with pytest.raises(CRSError, match="not projected"):
        synthesize_divide_tree(small_type, size_m=SIZE, crs="EPSG:4326", rng=0)


def test_output_crs_in_feet_is_refused_up_front(small_type):
    """A projected CRS in US survey feet: refused before the synthesis, naming the unit and the fix (before: a
    tree synthesized with metres as feet, then the renderer's message about reprojecting the input DEM)."""
    with pytest.raises(CRSError, match=r"is in US survey foot units \(0.3048006 m\): synthesis works in metres"):
        synthesize_divide_tree(small_type, size_m=SIZE, crs="EPSG:2227", rng=0)


def test_local_projection_centre(small_type):
    t = synthesize_divide_tree(small_type, size_m=SIZE, center=(7.5, 46.2), rng=0)
    pt = peaks_table(t)
    assert t.crs is not None
    assert abs(pt["lon"].mean() - 7.5) < 0.1 and abs(pt["lat"].mean() - 46.2) < 0.1
    assert (np.abs(pt["x"]) <= SIZE / 2).all()


def test_type_map_mixes_types(small_type):
    high = small_type.shifted("elevation", 3000.0)
    ct = np.zeros((32, 32))
    ct[:, 16:] = 1
    t = synthesize_divide_tree([small_type, high], size_m=SIZE, type_map=ct, rng=4)
    t.validate()
    east = t.peaks["x"].to_numpy() > SIZE / 2
    assert (t.peaks["type"].to_numpy() == east.astype(int)).all()
    assert t.peaks["elevation"][east].min() >= high.histograms["elevation"].edges[0] - 1e-6
    assert t.peaks["elevation"][~east].max() <= small_type.histograms["elevation"].edges[-1] + 1e-6
    with pytest.raises(InputError, match="type map values"):
        synthesize_divide_tree([small_type], size_m=SIZE, type_map=ct, rng=4)


def test_fragment_is_kept_and_completed(small_type, tree):
    frag = tree.subset(tree.peaks["x"].to_numpy() < 6000)  # a connected-by-bottleneck piece
    out = synthesize_divide_tree(small_type, size_m=SIZE, fragment=frag, fragment_offset=(1000.0, 0.0), rng=9)
    out.validate()
    px, py = out.peaks["x"].to_numpy(), out.peaks["y"].to_numpy()
    idx = [int(np.argmin(np.hypot(px - (x + 1000.0), py - y))) for x, y in zip(frag.peaks["x"], frag.peaks["y"])]
    ridges = {(min(a, b), max(a, b)): s for a, b, s in zip(out.edges["peak_a"], out.edges["peak_b"], out.edges["saddle"])}
    for a, b, s in zip(frag.edges["peak_a"], frag.edges["peak_b"], frag.edges["saddle"]):
        key = (min(idx[a], idx[b]), max(idx[a], idx[b]))
        assert key in ridges
        assert out.saddles["elevation"].iloc[ridges[key]] == pytest.approx(frag.saddles["elevation"].iloc[s])


def test_orometry_of_tiny_tree():
    from orokit.topology.divide_tree import DivideTree

    # three peaks in a row: 100 -- s80 -- 90 -- s50 -- 120 (x = 0, 1000, 1900)
    t = DivideTree.from_arrays([[0, 0, 100], [1000, 0, 90], [1900, 0, 120]],
                               [[500, 0, 80], [1450, 0, 50]], [[0, 1, 0], [1, 2, 1]])
    o = tree_orometry(t)
    assert o["prominence"].tolist() == [50.0, 10.0, 120.0]
    assert o["key_saddle"].tolist() == [1, 0, -1]
    # both lower peaks are isolated by the 120 m peak, east of them
    assert o["isolation"].tolist()[:2] == [1900.0, 900.0]
    assert o["isolation_direction"].tolist()[:2] == [0.0, 0.0]
    assert o["isolation_peak"].tolist() == [2, 2, -1]
    assert o["saddle_distance"].tolist()[:2] == [1450.0, 500.0]
    assert o["saddle_direction"].tolist()[:2] == [0.0, 180.0]


from hypothesis import example, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402


@settings(max_examples=12, deadline=None)
@given(n=st.integers(2, 120), seed=st.integers(0, 2**31), rho=st.sampled_from([0.0, 1.0, 2.0]),
       passes=st.integers(1, 5), scale=st.floats(0.3, 3.0))
@example(n=2, seed=0, rho=0.0, passes=2, scale=1.0)  # a first pass of one peak has no ridge
def test_any_synthesis_is_a_valid_tree(small_type, n, seed, rho, passes, scale):
    t = small_type.with_rho(rho).scaled("prominence", scale)
    tree = synthesize_divide_tree(t, size_m=SIZE, n_peaks=n, params=SynthesisParams(n_passes=passes), rng=seed)
    tree.validate()
    assert tree.n_peaks == n and len(tree.edges) == n - 1 and _components(tree) == 1
    table = tree.prominence_table()
    eps = t.min_prominence_m
    assert (table.loc[table["key_saddle"] >= 0, "prominence"] >= eps - 1e-9).all()
    x, y = tree.peaks["x"].to_numpy(), tree.peaks["y"].to_numpy()
    assert ((x >= 0) & (x <= SIZE) & (y >= 0) & (y <= SIZE)).all()


def test_domain_conflicts_with_size_crs_center(small_type):
    from orokit.synthesis.controls import make_domain

    dom = make_domain(SIZE, crs="EPSG:32633")
    tree = synthesize_divide_tree(small_type, domain=dom, n_peaks=30, rng=2)
    assert tree.crs.to_epsg() == 32633 and tree.attrs["domain"]["width"] == dom.width
    for kw in ({"size_m": SIZE}, {"crs": "EPSG:32633"}, {"center": (7.0, 46.0)}):
        with pytest.raises(InputError, match=f"either domain= or {next(iter(kw))}, not both"):
            synthesize_divide_tree(small_type, domain=dom, n_peaks=30, rng=2, **kw)
    with pytest.raises(InputError, match="domain must be"):
        synthesize_divide_tree(small_type, domain=(0, 0, 10, 10), n_peaks=30, rng=2)


@pytest.mark.parametrize("kw, msg", [({"saddle_placement": "random"}, "saddle_placement"),
                                     ({"use_bands": "yes"}, "use_bands"), ({"n_passes": 0}, "n_passes must be >= 1"),
                                     ({"auto_elevation_m": -5.0}, "auto_elevation_m")])
def test_synthesis_params_are_checked(kw, msg):
    with pytest.raises(InputError, match=msg):
        SynthesisParams(**kw)


def test_synthesis_params_are_frozen_and_typed(small_type):
    import dataclasses

    p = SynthesisParams(n_candidates=8)
    with pytest.raises(dataclasses.FrozenInstanceError):
        p.n_candidates = 9  # type: ignore[misc]
    with pytest.raises(InputError, match="params must be a SynthesisParams"):
        synthesize_divide_tree(small_type, size_m=SIZE, params={"n_candidates": 8}, rng=1)


def test_void_weight_fills_the_holes_between_peaks(small_type):
    """With void_weight, lower peaks are drawn into the holes the earlier passes left: the
    largest distance from a point of the domain to its nearest peak shrinks (measured with a
    KD-tree on a grid of points, not by the synthesis), the histograms stay matched."""
    from scipy.spatial import cKDTree

    from orokit.synthesis.fidelity import compare_to_type
    from orokit.synthesis.tree import SynthesisParams

    def gap_q90(tree):
        g = np.stack(np.meshgrid(np.linspace(0, SIZE, 120), np.linspace(0, SIZE, 120)), -1).reshape(-1, 2)
        return float(np.quantile(cKDTree(tree.peaks[["x", "y"]].to_numpy(float)).query(g)[0], 0.9))

    plain, filled = [], []
    for seed in range(3):
        plain.append(gap_q90(synthesize_divide_tree(small_type, size_m=SIZE, rng=seed,
                                                    params=SynthesisParams(void_weight=0.0))))
        t = synthesize_divide_tree(small_type, size_m=SIZE, rng=seed, params=SynthesisParams(void_weight=1.0))
        filled.append(gap_q90(t))
        assert compare_to_type(t, small_type)["max_bin_error"].max() < 0.2
    assert np.mean(filled) < np.mean(plain)
    with pytest.raises(InputError, match="void_weight"):
        SynthesisParams(void_weight=-1.0)
