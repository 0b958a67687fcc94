"""Rusnell 2009 backend: plain fields equal scipy's Dijkstra, generators fixed, blending, bad inputs."""
from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

from orokit.errors import InputError
from orokit.generators import _rusnell_kernels as K
from orokit.generators import render_terrain
from orokit.generators import rusnell as R
from orokit.raster.rasterize import make_grid

from helpers.trees import small_tree


def grid_graph(w: np.ndarray) -> sp.csr_matrix:
    """The 8-connected grid graph with the kernel's forward edge weights (ny, nx, 4)."""
    ny, nx, _ = w.shape
    rows, cols, vals = [], [], []
    for k in range(4):
        di, dj = int(K.DI[k]), int(K.DJ[k])
        for i in range(ny):
            for j in range(nx):
                r, q = i + di, j + dj
                if 0 <= r < ny and 0 <= q < nx:
                    rows.append(i * nx + j)
                    cols.append(r * nx + q)
                    vals.append(w[i, j, k])
    m = sp.coo_matrix((vals, (rows, cols)), shape=(ny * nx, ny * nx)).tocsr()
    return m + m.T


def _field(w, gens, costs, cs, table=np.ones(2), use_profile=False, ca=np.zeros((0, 0)), halt=0.0,
           stop=np.zeros((0, 0), np.uint8)):
    ny, nx, _ = w.shape
    stamp = np.full((ny, nx), -1, np.int32)
    fixed = np.full((ny, nx), -1, np.int32)
    cost, src = np.zeros((ny, nx)), np.zeros((ny, nx))
    touched = np.empty(ny * nx, np.int64)
    gi = np.array([g[0] for g in gens], np.int64)
    gj = np.array([g[1] for g in gens], np.int64)
    m = K.cost_field(w, gi, gj, np.asarray(costs, float), cs, table, use_profile, ca, halt, stamp, 1, cost, src,
                     touched, fixed, stop)
    return np.where(stamp == 1, cost, np.inf), m


@pytest.mark.parametrize("r", [0.0, 0.4])
def test_plain_field_equals_scipy_dijkstra(r):
    rng = np.random.default_rng(0)
    mu = 1.5
    w = R.edge_weights(21, 17, mu, r, rng)
    got, m = _field(w, [(10, 8)], [0.0], cs=1e9)
    ref = dijkstra(grid_graph(w), indices=10 * 17 + 8).reshape(21, 17)
    np.testing.assert_allclose(got, ref, rtol=1e-12)
    assert m == 21 * 17
    if r == 0.0:  # a lone generator: 8-neighbour distance (1 or sqrt 2 per step) x mu_w
        ii, jj = np.mgrid[0:21, 0:17]
        di, dj = np.abs(ii - 10), np.abs(jj - 8)
        octile = (np.maximum(di, dj) - np.minimum(di, dj)) + math.sqrt(2) * np.minimum(di, dj)
        np.testing.assert_allclose(got, mu * octile, rtol=1e-12)


def test_generators_are_never_relaxed_and_the_peak_is_the_feature_maximum():
    w = R.edge_weights(15, 15, 1.0, 0.0, np.random.default_rng(1))
    # a "peak" at cost 0 and a ridge of generators whose costs rise faster than the edges
    gens = [(7, 7), (7, 8), (7, 9), (7, 10)]
    costs = [0.0, 5.0, 10.0, 15.0]
    got, _ = _field(w, gens, costs, cs=100.0)
    for (i, j), c in zip(gens, costs):
        assert got[i, j] == c  # a path from the peak would be cheaper (1, 2, 3), generators keep their cost
    assert np.argmin(np.where(np.isfinite(got), got, np.inf)) == 7 * 15 + 7


def test_search_halts_near_sea_level_and_at_the_fraction_of_the_all_generator_field():
    w = R.edge_weights(31, 31, 1.0, 0.0, np.random.default_rng(2))
    got, m = _field(w, [(15, 15)], [0.0], cs=5.0)
    assert np.isfinite(got).sum() == m < 31 * 31
    assert got[np.isfinite(got)].max() < 5.0 + 1.5  # expanded only below cs - 0.5
    ca = np.zeros((31, 31))  # an all-generator field of full height everywhere
    got2, m2 = _field(w, [(15, 15)], [0.0], cs=20.0, ca=ca, halt=0.5)
    assert m2 < (np.isfinite(_field(w, [(15, 15)], [0.0], cs=20.0)[0])).sum()


def test_profile_scaling_follows_eq1():
    w = R.edge_weights(3, 40, 1.0, 0.0, np.random.default_rng(3))
    table = np.array([1.0, 3.0])  # w_s grows linearly from 1 at c_m = 0 to 3 at c_m = c_s
    got, _ = _field(w, [(1, 0)], [0.0], cs=100.0, table=table, use_profile=True)
    c = [0.0]
    for _ in range(5):  # along the row: c += w_e * w_s(c_m(c)), c_g = 0 so c_m = c
        c.append(c[-1] + 1.0 * (1.0 + 2.0 * c[-1] / 100.0))
    np.testing.assert_allclose(got[1, :6], c, rtol=1e-12)


def test_blend_is_the_mean_at_b0_and_never_exceeds_the_maximum():
    rng = np.random.default_rng(4)
    h = rng.uniform(0, 100, (5, 50))
    np.testing.assert_allclose(R.blend(h, 0.0), h.mean(axis=0))
    for b in (0.0, 1.0, 3.0, 4.0, 20.0):
        out = R.blend(h, b)
        assert (out <= h.max(axis=0) + 1e-9).all() and (out >= h.mean(axis=0) - 1e-9).all()
    # the kernel's accumulation gives the same as the array formula
    ny, nx = 1, 50
    num, den = np.zeros((ny, nx)), np.zeros((ny, nx))
    touched = np.arange(nx, dtype=np.int64)
    for f in range(5):
        K.blend_add(touched, nx, (100.0 - h[f])[None, :], 100.0, 3.0, num, den)
    np.testing.assert_allclose(num[0] / den[0], R.blend(h, 3.0))


def test_profile_fit_is_monotone_and_non_monotone_profiles_are_rejected():
    rng = np.random.default_rng(5)
    d = rng.uniform(0, 3000, 5000)
    drop = 400 * np.sqrt(d / 3000) + rng.normal(0, 30, d.size)
    dist, prof = R.fit_profile(d, drop)
    assert dist[0] == 0 and prof[0] == 0 and (np.diff(prof) >= 0).all()
    assert prof[-1] == pytest.approx(400 * np.sqrt(dist[-1] / 3000), abs=30)
    tab = R.slope_table(dist, prof, cs=1000.0, mu_w=1.0)
    assert (tab > 0).all() and tab[0] > tab[-1]  # concave profile: steep near the peak
    with pytest.raises(InputError, match="monotone"):
        R.slope_table(np.array([0.0, 1.0, 2.0]), np.array([0.0, 5.0, 3.0]), cs=10.0, mu_w=1.0)


@pytest.mark.parametrize("bad", [{"r": 0.75}, {"r": 2.0}, {"mu_w": 0.0}, {"s": 1.0}, {"b": -1.0},
                                 {"preset": "volcano"}, {"profile": "hand"}])
def test_out_of_range_parameters_are_refused(bad):
    with pytest.raises(InputError):
        R.RusnellParams(**bad)


def test_presets_are_table_1():
    p = R.RusnellParams(preset="crater")
    assert (p.mu_w, p.r, p.s, p.b) == (1.5, 1.0, 1.1, 4.0)
    assert R.RusnellParams(preset="cinder-cone", b=5.0).b == 5.0


def test_render_without_exemplar_needs_profile_none():
    tree = small_tree()
    with pytest.raises(InputError, match="exemplar"):
        render_terrain(tree, generator="rusnell", cell_size_m=200.0, seed=0)
    a = render_terrain(tree, generator="rusnell", cell_size_m=200.0, params={"profile": "none"}, seed=0)
    b = render_terrain(tree, generator="rusnell", cell_size_m=200.0, params={"profile": "none"}, seed=0)
    assert a.values.tobytes() == b.values.tobytes()
    z = a.values
    grid = make_grid((0.0, 0.0, 8000.0, 8000.0), 200.0)
    row, col, _ = grid.cell_of(tree.peaks[["x", "y"]].to_numpy())
    # the highest peak is the highest cell; the blend lowers no cell above it
    assert z.max() == pytest.approx(1500.0, abs=1e-3) and z[row[0], col[0]] == z.max()


def _bumps_exemplar(grid):
    """An exemplar DEM: three Gaussian hills on a 300 m plain."""
    from orokit.generators.base import as_dataarray

    x, y = grid.centres()
    bumps = sum(h * np.exp(-((x[None, :] - cx) ** 2 + (y[:, None] - cy) ** 2) / 6e5)
                for cx, cy, h in ((2000, 2000, 600), (6000, 5000, 500), (3000, 6500, 400)))
    return as_dataarray(300 + bumps, grid, None)


def test_render_with_an_exemplar_profile():
    tree = small_tree()
    grid = make_grid((0.0, 0.0, 8000.0, 8000.0), 100.0)
    ex = _bumps_exemplar(grid)
    dem = render_terrain(tree, generator="rusnell", cell_size_m=100.0, exemplar=ex, seed=1)
    assert np.isfinite(dem.values).all() and dem.values.max() <= 1500.0 + 1e-3


def test_a_fitted_profile_passed_in_gives_the_same_raster():
    """`learn` + `inputs={"learned": ...}` (the benchmark's cached profile fit) renders the same bytes."""
    tree = small_tree()
    grid = make_grid((0.0, 0.0, 8000.0, 8000.0), 100.0)
    ex = _bumps_exemplar(grid)
    direct = render_terrain(tree, generator="rusnell", grid=grid, exemplar=ex, seed=2)
    prof = R.learn(ex, grid, R.RusnellParams(), np.random.default_rng(2))
    cached = render_terrain(tree, generator="rusnell", grid=grid, exemplar=ex, seed=2, inputs={"learned": prof})
    assert cached.values.tobytes() == direct.values.tobytes()


def test_sea_level_puts_the_plain_at_the_exemplar_floor_or_s_reliefs_down():
    """`sea_level`: the plain (cells no feature reaches) at the exemplar's 1st percentile (auto
    with an exemplar) or at highest peak - s x the largest generator cost (preset, the paper)."""
    from orokit.generators.base import as_dataarray

    tree = small_tree()  # peaks 1500 .. 1000 m, lowest saddle 900 m
    grid = make_grid((0.0, 0.0, 16000.0, 16000.0), 100.0)  # room beyond the features' reach
    x, y = grid.centres()
    ex = as_dataarray(200 + 600 * np.exp(-((x[None, :] - 3000) ** 2 + (y[:, None] - 3000) ** 2) / 4e6), grid, None)
    floor = float(np.quantile(ex.values, 0.01))
    auto = render_terrain(tree, generator="rusnell", grid=grid, exemplar=ex, seed=0,
                          params={"profile": "none", "sea_level": "exemplar"})
    preset = render_terrain(tree, generator="rusnell", grid=grid, exemplar=ex, seed=0,
                            params={"profile": "none", "sea_level": "preset"})
    top = float(tree.peaks["elevation"].max())
    cmax = top - float(tree.saddles["elevation"].min())
    assert float(auto.values.min()) == pytest.approx(top - max(top - floor, 1.05 * cmax), abs=0.01)
    assert float(preset.values.min()) == pytest.approx(top - 2.5 * cmax, abs=0.01)  # foothills s = 2.5
    assert float(auto.values.max()) == pytest.approx(top, abs=1e-3)
    with pytest.raises(InputError, match="sea_level"):
        R.RusnellParams(sea_level="lake")
    with pytest.raises(InputError, match="cap_quantile"):
        R.RusnellParams(cap_quantile=1.5)


def _octile_m(i, j, ri, rj, cell):
    di, dj = np.abs(i[:, None] - ri[None, :]), np.abs(j[:, None] - rj[None, :])
    return cell * (np.maximum(di, dj) + (math.sqrt(2.0) - 1.0) * np.minimum(di, dj))


def test_river_plain_is_the_bed_plus_slope_times_the_grid_distance():
    """`river_plain` = min over river cells (bed + slope x 8-connected distance), against brute force."""
    from orokit.raster.rasterize import Grid
    from orokit.raster.rivers import RiverNetwork

    grid = Grid(x0=0.0, y0=3000.0, cell_size_m=100.0, ny=30, nx=25)
    riv = RiverNetwork(xy=np.array([[50.0, 150.0], [1250.0, 1450.0], [2350.0, 2850.0]]),
                       elevation=np.array([100.0, 160.0, 400.0]), receiver=np.array([-1, 0, 1]),
                       length=np.array([0.0, 1767.8, 1802.8]), order=np.array([0, 1, 2]),
                       outlet=np.array([True, False, False]))
    got = R.river_plain(riv, grid, slope=0.3)
    from orokit.generators.belhadj import _densify

    e = riv.edges()
    xy, h = _densify(riv.xy[e[:, 0]], riv.xy[e[:, 1]], riv.elevation[e[:, 0]], riv.elevation[e[:, 1]], 50.0)
    row, col, _ = grid.cell_of(xy)
    bed = {}
    for r, c, z in zip(row, col, h):
        bed[(r, c)] = min(bed.get((r, c), np.inf), z)
    ri, rj = np.array([k[0] for k in bed]), np.array([k[1] for k in bed])
    rz = np.array(list(bed.values()))
    i, j = np.divmod(np.arange(grid.ny * grid.nx), grid.nx)
    want = (rz[None, :] + 0.3 * _octile_m(i, j, ri, rj, 100.0)).min(axis=1).reshape(grid.ny, grid.nx)
    np.testing.assert_allclose(got, want, rtol=1e-9)
    cap = R.generator_cap(np.array([3, 20]), np.array([4, 10]), np.array([0.0, 300.0]), 1000.0, grid, slope=0.5)
    wantc = (np.array([1000.0, 700.0])[None, :] - 0.5 * _octile_m(i, j, np.array([3, 20]), np.array([4, 10]),
                                                                  100.0)).max(axis=1).reshape(grid.ny, grid.nx)
    np.testing.assert_allclose(cap, wantc, rtol=1e-9)


def test_sea_level_rivers_lifts_the_plain_and_keeps_the_generators():
    """`sea_level=rivers` (the default with an exemplar and rivers): the plain rises from the rivers,
    nothing is lowered, the generator cells keep their elevation, and fewer cells are flat."""
    from orokit.generators.base import as_dataarray

    tree = small_tree()
    grid = make_grid((0.0, 0.0, 16000.0, 16000.0), 100.0)
    x, y = grid.centres()
    hills = 150 * np.sin(x[None, :] / 400.0) * np.sin(y[:, None] / 400.0)  # slopes of ~15 deg
    ex = as_dataarray(500 + 600 * np.exp(-((x[None, :] - 3000) ** 2 + (y[:, None] - 3000) ** 2) / 4e6) + hills,
                      grid, None)
    flat = render_terrain(tree, generator="rusnell", grid=grid, exemplar=ex, seed=0, params={"sea_level": "exemplar"})
    auto = render_terrain(tree, generator="rusnell", grid=grid, exemplar=ex, seed=0)
    rivers = render_terrain(tree, generator="rusnell", grid=grid, exemplar=ex, seed=0, params={"sea_level": "rivers"})
    assert auto.values.tobytes() == rivers.values.tobytes()
    a, b = flat.values.astype(float), rivers.values.astype(float)
    assert (b >= a - 1e-3).all() and (b[80:, :80] > a[80:, :80] + 1.0).mean() > 0.3
    for fi, fj, fz in R.features(tree, grid):
        np.testing.assert_allclose(b[fi, fj], a[fi, fj], atol=1e-3)
    assert b.max() == pytest.approx(a.max(), abs=1e-3)
    # the saddle cap: a peak above its 8 neighbours on the flat plain stays so (the plain buries none)
    row, col, _ = grid.cell_of(tree.peaks[["x", "y"]].to_numpy())
    n_top = 0
    for r, c in zip(row, col):
        if a[r, c] >= a[r - 1:r + 2, c - 1:c + 2].max() - 1e-3:
            n_top += 1
            assert b[r, c] >= b[r - 1:r + 2, c - 1:c + 2].max() - 1e-3
    assert n_top >= 3
    lifted = render_terrain(tree, generator="rusnell", grid=grid, exemplar=ex, seed=0,
                            params={"sea_level": "rivers", "saddle_cap": False})
    assert (lifted.values >= b - 1e-3).all()  # the cap only lowers the plain

    def flat_share(z):
        gy, gx = np.gradient(z, 100.0)
        return float((np.degrees(np.arctan(np.hypot(gx, gy))) < 2.0).mean())

    inside = np.s_[80:, :80]  # the tree's 8 x 8 km (rows from the north)
    assert flat_share(b[inside]) < 0.5 * flat_share(a[inside])
    with pytest.raises(InputError, match="exemplar"):
        render_terrain(tree, generator="rusnell", grid=grid, seed=0, params={"sea_level": "rivers", "profile": "none"})


def test_water_halts_the_search():
    """A river row is reached but never crossed: the cells beyond it stay unreached."""
    w = R.edge_weights(15, 12, 1.0, 0.0, np.random.default_rng(0))
    stop = np.zeros((15, 12), np.uint8)
    stop[7, :] = 1
    got, m = _field(w, [(2, 5)], [0.0], cs=1e9, stop=stop)
    assert np.isfinite(got[:8]).all() and np.isinf(got[8:]).all()
    assert m == 8 * 12
    free, _ = _field(w, [(2, 5)], [0.0], cs=1e9)
    np.testing.assert_array_equal(got[:8], free[:8])  # above the river: the same least costs (no detour is shorter)


def test_secondary_paths_descend_to_a_generator():
    rng = np.random.default_rng(1)
    w = R.edge_weights(30, 30, 1.0, 0.5, rng)
    gens = [(5, 5), (20, 24)]
    ca, _ = _field(w, gens, [0.0, 10.0], cs=1e9)
    gmask = np.zeros((30, 30), bool)
    for g in gens:
        gmask[g] = True
    starts = rng.choice(900, size=25, replace=False)
    for p in R.secondary_paths(ca, gmask, starts):
        c = ca.ravel()[p]
        assert (np.diff(c) < 0).all()  # strictly down the least-cost field
        assert gmask.ravel()[p[-1]]
        steps = np.abs(np.diff(np.column_stack(np.divmod(p, 30)), axis=0))
        assert (steps.max(axis=1) == 1).all()  # 8-neighbour steps


def test_render_with_secondary_ridges_and_water():
    tree = small_tree()
    base = render_terrain(tree, generator="rusnell", cell_size_m=100.0, seed=0, params={"profile": "none"})
    sec = render_terrain(tree, generator="rusnell", cell_size_m=100.0, seed=0,
                         params={"profile": "none", "secondary": 30})
    assert not np.array_equal(base.values, sec.values)
    again = render_terrain(tree, generator="rusnell", cell_size_m=100.0, seed=0,
                           params={"profile": "none", "secondary": 30})
    assert again.values.tobytes() == sec.values.tobytes()
    wet = render_terrain(tree, generator="rusnell", cell_size_m=100.0, seed=0,
                         params={"profile": "none", "water": True})
    assert not np.array_equal(base.values, wet.values)


def test_generators_table_replaces_the_tree():
    import pandas as pd

    grid = make_grid((0.0, 0.0, 8000.0, 8000.0), 100.0)
    table = pd.DataFrame({"x": [2050.0, 2150.0, 6050.0], "y": [2050.0, 2050.0, 6050.0], "cost": [0.0, 0.0, 300.0],
                          "feature": [1, 1, 2]})
    feats = R.file_features(table, grid)
    assert [f[0].size for f in feats] == [2, 1]
    p = R.RusnellParams(profile="none", r=0.0)
    dem = R.render(small_tree(), None, grid, np.random.default_rng(0), p, generators=table)
    z = dem.values
    cs = p.s * 300.0
    assert float(z.max()) == pytest.approx(cs)  # the zero-cost generators are the highest ground, at c_s
    assert z[59, 20] == pytest.approx(cs) and z[19, 60] < z[59, 20]
    for bad, msg in ((table.drop(columns="cost"), "lacks the column"), (table.assign(cost=-1.0), ">= 0"),
                     (table.assign(x=1e7), "inside the grid")):
        with pytest.raises(InputError, match=msg):
            R.file_features(bad, grid)
    with pytest.raises(InputError, match="caller reads"):
        render_terrain(small_tree(), generator="rusnell", cell_size_m=100.0, seed=0,
                       params={"profile": "none", "generators": "g.csv"})


def test_cli_render_rusnell_from_a_generators_file(tmp_path):
    import rasterio
    from click.testing import CliRunner

    from orokit.cli.main import cli
    from orokit.io.divide_tree_io import write_divide_tree_gpkg

    write_divide_tree_gpkg(small_tree(crs="EPSG:32633"), tmp_path / "tree.gpkg")
    (tmp_path / "gen.csv").write_text("x,y,cost,feature\n2050,2050,0,1\n6050,6050,200,2\n")
    args = ["render", str(tmp_path / "tree.gpkg"), "-o", str(tmp_path / "dem.tif"), "--resolution", "100m",
            "--generator", "rusnell", "--param", "profile=none", "--param", f"generators={tmp_path / 'gen.csv'}",
            "--seed", "0"]
    r = CliRunner().invoke(cli, args)
    assert r.exit_code == 0, r.output
    with rasterio.open(tmp_path / "dem.tif") as src:
        assert len(src.tags()["generators_sha256"]) == 64
        z = src.read(1)
    assert z[59, 20] == pytest.approx(z.max())  # the zero-cost generator is the summit
    bad = CliRunner().invoke(cli, args[:3] + [str(tmp_path / "bad.tif")] + args[4:8] + ["--param", "generators=no.csv"])
    assert bad.exit_code != 0 and "generators=no.csv" in bad.output and "Traceback" not in bad.output
