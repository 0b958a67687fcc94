"""Michel 2015 backend: exact sub-plate velocities, merging rules, folds as translations, drainage."""
from __future__ import annotations

import json

import numpy as np
import pytest

from orokit.errors import InputError
from orokit.generators import michel as M
from orokit.generators import render_terrain
from orokit.generators.base import tree_rivers
from orokit.raster.rasterize import make_grid

from helpers.trees import small_tree


def _peaks(n, seed, size=8000.0):
    return np.random.default_rng(seed).uniform(0.05 * size, 0.95 * size, (n, 2))


def test_sub_plate_velocities_are_exact():
    grid = make_grid((0.0, 0.0, 4000.0, 3000.0), 100.0)
    pk = _peaks(7, 0, 3000.0)
    plates = M.sub_plates(pk, grid)
    x, y = grid.centres()
    for k in range(7):  # brute force: the cells nearest to peak k, their centre of mass
        cells = [(xi, yi) for yi in y for xi in x
                 if np.argmin(np.hypot(pk[:, 0] - xi, pk[:, 1] - yi)) == k]
        c = np.mean(cells, axis=0)
        np.testing.assert_allclose(plates.velocity[k], pk[k] - c, atol=1e-9)
        assert plates.area[k] == pytest.approx(len(cells) * 100.0**2)


@pytest.mark.parametrize("seed", [1, 2])
@pytest.mark.parametrize("t1, t2", [(0.9, 0.0), (0.5, 0.05), (0.0, 0.2)])
def test_after_merging_no_pair_above_t1_and_no_plate_below_t2(seed, t1, t2):
    grid = make_grid((0.0, 0.0, 8000.0, 8000.0), 100.0)
    merged = M.merge_plates(M.sub_plates(_peaks(40, seed), grid), t1=t1, t2=t2)
    u = M._unit(merged.velocity)
    for a, b in M._adjacent_pairs(merged.label):
        assert float(u[a] @ u[b]) <= t1 + 1e-12
    nb: dict[int, set[int]] = {}
    for a, b in M._adjacent_pairs(merged.label):
        nb.setdefault(a, set()).add(b)
        nb.setdefault(b, set()).add(a)
    for a, ns in nb.items():
        assert merged.area[a] / max(merged.area[c] for c in ns) >= t2
    # areas add up, and each merged velocity is the area-weighted mean of its sub-plates
    sub = M.sub_plates(_peaks(40, seed), grid)
    assert merged.area.sum() == pytest.approx(sub.area.sum())
    for p in range(merged.n):
        members = np.unique(sub.label[merged.label == p])
        w = sub.area[members]
        np.testing.assert_allclose(merged.velocity[p], (w[:, None] * sub.velocity[members]).sum(0) / w.sum(),
                                   atol=1e-6)


@pytest.mark.parametrize("seed", [3, 4, 5])
def test_a_smaller_t1_never_gives_more_plates(seed):
    # without the area rule (t2 = 0): with it, absorbing small plates can cascade differently
    grid = make_grid((0.0, 0.0, 8000.0, 8000.0), 100.0)
    sub = M.sub_plates(_peaks(60, seed), grid)
    counts = [M.merge_plates(sub, t1=t1, t2=0.0).n for t1 in (0.99, 0.9, 0.7, 0.5, 0.2, 0.0, -0.5)]
    assert counts == sorted(counts, reverse=True) and counts[0] > counts[-1]


def test_far_from_plate_boundaries_folds_are_a_translation_of_the_fbm():
    res = 50.0
    grid = make_grid((0.0, 0.0, 4000.0, 2000.0), res)  # 40 x 80 cells
    label = np.zeros((grid.ny, grid.nx), np.int64)
    label[:, 40:] = 1
    plates = M.Plates(label, np.array([1.0, 1.0]), np.array([[3 * res, 0.0], [-2 * res, 1 * res]]))
    vel = M.velocity_map(plates, res, blur_m=2 * res)  # sigma 2 cells, truncated at 8
    pad = 6
    noise = M.fbm((grid.ny + 2 * pad, grid.nx + 2 * pad), 3.0, np.random.default_rng(0))
    f = M.fold_map(noise, pad, vel, res)
    # left plate (cols < 31): shifted 3 cells east; right plate (cols > 49): 2 west, 1 north
    np.testing.assert_allclose(f[:, :31], noise[pad:pad + grid.ny, pad + 3:pad + 3 + 31], atol=1e-6)
    np.testing.assert_allclose(f[:, 50:], noise[pad - 1:pad - 1 + grid.ny, pad - 2 + 50:pad - 2 + grid.nx], atol=1e-6)
    # near the boundary the velocity varies: there the folds are not a translation
    assert not np.allclose(f[:, 38:42], noise[pad:pad + grid.ny, pad + 3 + 38:pad + 3 + 42], atol=1e-3)


def test_watershed_drains_every_cell():
    tree = small_tree()
    grid = make_grid((0.0, 0.0, 8000.0, 8000.0), 100.0)
    g, river = M.watershed_map(tree_rivers(tree, grid), grid, river_slope=0.005, hill_slope=0.05)
    assert river.sum() > 50 and np.isfinite(g).all()
    pad = np.pad(g, 1, constant_values=np.inf)
    lower = np.zeros(g.shape, bool)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            if di or dj:
                lower |= pad[1 + di:1 + di + g.shape[0], 1 + dj:1 + dj + g.shape[1]] < g
    interior = np.zeros(g.shape, bool)
    interior[1:-1, 1:-1] = True
    assert lower[interior].all()  # every interior cell has a strictly lower neighbour: water reaches the border
    assert g[~interior].min() == pytest.approx(g.min())


@pytest.mark.parametrize("bad", [{"t1": 1.5}, {"t2": 1.0}, {"blur_m": 0.0}, {"k_min": 1.0}, {"fbm_beta": 6.0},
                                 {"river_slope": 0.2, "hill_slope": 0.1}, {"valley_slope": -0.1},
                                 {"valley_slope": float("inf")}])
def test_out_of_range_parameters_are_refused(bad):
    with pytest.raises(InputError):
        M.MichelParams(**bad)


def test_render_scales_to_the_tree_relief():
    tree = small_tree()
    dem = render_terrain(tree, generator="michel", cell_size_m=100.0, params={"erosion": False}, seed=2)
    z = dem.values
    assert np.isfinite(z).all() and z.max() <= 1500.0 + 1e-3
    assert z.max() - z.min() > 300.0


def _plane(slope, grid):
    from orokit.generators.base import as_dataarray

    x, _ = grid.centres()
    return as_dataarray(np.broadcast_to(slope * (x - x[0]), (grid.ny, grid.nx)), grid, "EPSG:32633")


def test_exemplar_slope_of_a_plane_is_its_gradient():
    from orokit.generators.base import exemplar_slope

    grid = make_grid((0.0, 0.0, 8000.0, 8000.0), 100.0)
    assert exemplar_slope(_plane(0.3, grid)) == pytest.approx(0.3, rel=1e-9)
    with pytest.raises(InputError, match="exemplar"):
        exemplar_slope(_plane(0.3, grid).where(False))


def test_valley_sides_follow_the_valley_slope_and_the_exemplar():
    tree = small_tree("EPSG:32633")
    grid = make_grid((0.0, 0.0, 8000.0, 8000.0), 50.0)

    def mean_slope(dem):
        gy, gx = np.gradient(dem.values.astype(float), 50.0)
        return float(np.hypot(gx, gy).mean())

    base = {"erosion": False}
    gentle = render_terrain(tree, generator="michel", grid=grid, params={**base, "valley_slope": 0.05}, seed=3)
    steep = render_terrain(tree, generator="michel", grid=grid, params={**base, "valley_slope": 0.5}, seed=3)
    assert mean_slope(steep) > mean_slope(gentle)
    assert json.loads(steep.attrs["derived"])["valley_slope"] == 0.5
    # NaN (the default) takes the exemplar's mean slope; without an exemplar, mask_m (= valley_slope 0)
    ex = render_terrain(tree, generator="michel", grid=grid, params=base, seed=3, exemplar=_plane(0.5, grid))
    np.testing.assert_array_equal(ex.values, steep.values)
    plain = render_terrain(tree, generator="michel", grid=grid, params=base, seed=3)
    fixed = render_terrain(tree, generator="michel", grid=grid, params={**base, "valley_slope": 0.0}, seed=3)
    np.testing.assert_array_equal(plain.values, fixed.values)
    assert json.loads(plain.attrs["derived"])["mask_m"] == M.MichelParams().mask_m


# ----------------------------------------------------------------------------- plain mode: a vector map
def _island_map():
    from shapely.geometry import Polygon

    land = Polygon([(800.0, 800.0), (7200.0, 800.0), (7200.0, 7200.0), (800.0, 7200.0)])
    peaks = np.array([[3000.0, 3000.0], [5000.0, 3500.0], [4000.0, 5200.0], [2500.0, 5500.0]])
    # a river from the interior to the coast, and a tributary ending on it (both source -> mouth)
    main = np.array([[4000.0, 4200.0], [4000.0, 2500.0], [4000.0, 820.0]])
    trib = np.array([[5600.0, 5000.0], [4000.0, 3000.0]])
    return M.VectorMap(peaks=peaks, rivers=(main, trib), land=land, top_m=1800.0)


def test_map_watershed_rises_from_the_sea_along_the_rivers():
    grid = make_grid((0.0, 0.0, 8000.0, 8000.0), 100.0)
    vmap = _island_map()
    g, river, land = M.map_watershed(vmap, grid, river_slope=0.01, hill_slope=0.1)
    assert (g[~land] == 0).all() and land.sum() == 64 * 64
    # the main river: 0 at its mouth on the coast, rising 0.01 m/m upstream
    col = 40
    rows = np.flatnonzero(river[:, col])
    assert rows.size > 30
    x, y = grid.centres()
    np.testing.assert_allclose(g[rows, col], 0.01 * (y[rows] - 820.0), atol=0.01 * grid.cell_size_m)
    # the tributary starts at the main river's height at the junction (y = 3000 m: 21.8 m), not at 0
    i, j, _ = grid.cell_of(np.array([[4700.0, 3875.0]]))
    assert river[i[0], j[0]] and g[i[0], j[0]] > 0.01 * (3000.0 - 820.0)
    # every land cell drains: some neighbour is lower, down to a river or the sea
    inner = g[1:-1, 1:-1]
    nb = np.min([g[1 + di:g.shape[0] - 1 + di, 1 + dj:g.shape[1] - 1 + dj]
                 for di in (-1, 0, 1) for dj in (-1, 0, 1) if di or dj], axis=0)
    src = (river | ~land)[1:-1, 1:-1]
    assert (nb[~src] < inner[~src]).all()


def test_render_from_a_vector_map_keeps_the_sea_and_the_top():
    vmap = _island_map()
    tree = small_tree()
    dem = render_terrain(tree, generator="michel", cell_size_m=100.0, seed=1, params={"erosion": False},
                         inputs={"map": vmap})
    z = dem.values
    grid = make_grid((0.0, 0.0, 8000.0, 8000.0), 100.0)
    land = M.land_mask(vmap, grid)
    assert (z[~land] == 0).all()
    assert z[land].max() <= 1800.0 + 1e-3 and z[land].max() > 900.0
    again = render_terrain(tree, generator="michel", cell_size_m=100.0, seed=1, params={"erosion": False},
                           inputs={"map": vmap})
    assert again.values.tobytes() == z.tobytes()
    # the plates come from the map's four peaks, not the tree's five
    assert json.loads(dem.attrs["cell_counts"])["plates"] <= 4
    with pytest.raises(InputError, match="caller reads"):
        render_terrain(tree, generator="michel", cell_size_m=100.0, seed=1, params={"map": "x.gpkg"})


def test_cli_render_michel_from_a_vector_map_file(tmp_path):
    import geopandas as gpd
    import rasterio
    from click.testing import CliRunner
    from shapely.geometry import LineString, Point

    from orokit.cli.main import cli
    from orokit.io.divide_tree_io import write_divide_tree_gpkg

    vmap = _island_map()
    geoms = [Point(*p) for p in vmap.peaks] + [LineString(r) for r in vmap.rivers] + [vmap.land]
    elev = [1800.0, 1500.0, 1600.0, 1200.0] + [None] * 3
    gpd.GeoDataFrame({"elevation": elev}, geometry=geoms, crs="EPSG:32633").to_file(tmp_path / "map.geojson")
    write_divide_tree_gpkg(small_tree(crs="EPSG:32633"), tmp_path / "tree.gpkg")
    args = ["render", str(tmp_path / "tree.gpkg"), "-o", str(tmp_path / "dem.tif"), "--resolution", "100m",
            "--generator", "michel", "--param", "erosion=false", "--param", f"map={tmp_path / 'map.geojson'}",
            "--seed", "0"]
    r = CliRunner().invoke(cli, args)
    assert r.exit_code == 0, r.output
    with rasterio.open(tmp_path / "dem.tif") as src:
        assert len(src.tags()["map_sha256"]) == 64
        z = src.read(1)
    from orokit.io.vector_map_io import read_vector_map

    read = read_vector_map(tmp_path / "map.geojson")
    assert read.top_m == 1800.0 and read.peaks.shape == (4, 2) and len(read.rivers) == 2 and read.land is not None
    same = render_terrain(small_tree(crs="EPSG:32633"), generator="michel", cell_size_m=100.0, seed=0,
                          params={"erosion": False}, inputs={"map": read})
    np.testing.assert_array_equal(z, same.values)
    assert z.min() == 0.0 and 900.0 < z.max() <= 1800.0 + 1e-3
    (tmp_path / "empty.geojson").write_text('{"type": "FeatureCollection", "features": []}')
    for bad, msg in (("no.gpkg", "does not exist"), (str(tmp_path / "empty.geojson"), "no point")):
        out = CliRunner().invoke(cli, args[:3] + [str(tmp_path / "bad.tif")] + args[4:10] + ["--param", f"map={bad}"])
        assert out.exit_code != 0 and msg in out.output and "Traceback" not in out.output
