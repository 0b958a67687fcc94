"""Guérin 2016 backend: exact reconstruction, sparsity and dictionary size, real atoms, amplification."""
from __future__ import annotations

import numpy as np
import pytest

from orokit.errors import InputError
from orokit.generators import render_terrain
from orokit.generators.guerin import GuerinParams, build_dictionary, sparse_codes, synthesize, weight_kernel

from helpers.trees import small_tree


def fractal(n: int, seed: int, beta: float = 3.0) -> np.ndarray:
    """A random terrain with a power-law spectrum (numpy FFT), in metres."""
    rng = np.random.default_rng(seed)
    k = np.hypot(*np.meshgrid(np.fft.fftfreq(n), np.fft.fftfreq(n), indexing="ij"))
    k[0, 0] = 1.0
    spec = (rng.normal(size=(n, n)) + 1j * rng.normal(size=(n, n))) * k ** (-beta / 2)
    spec[0, 0] = 0.0
    z = np.fft.ifft2(spec).real
    return 1000.0 + 300.0 * z / z.std()


def block_mean(z: np.ndarray, f: int) -> np.ndarray:
    n0, n1 = z.shape[0] // f * f, z.shape[1] // f * f
    return z[:n0, :n1].reshape(n0 // f, f, n1 // f, f).mean(axis=(1, 3))


def test_weights_are_the_papers_falloff():
    w = weight_kernel(8)
    c = np.arange(16) + 0.5 - 8
    r = np.hypot(c[:, None], c[None, :]) / 8
    assert np.allclose(w, np.where(r < 1, (1 - r**2) ** 3, 0.0))


@pytest.mark.parametrize("step", ["half-radius", "radius"])
@pytest.mark.parametrize("radius", [4, 8])
def test_complete_dictionary_at_s1_reconstructs_exactly(radius, step):
    z = fractal(96, 0)[:90, :77]  # not a multiple of the step: mirrored borders
    p = GuerinParams(radius=radius, factor=1, sparsity=1, dictionary="complete", step=step)
    d = build_dictionary(z, p, np.random.default_rng(0))
    rec = synthesize(z, d, 1, z.shape)
    assert rec.shape == z.shape
    assert np.abs(rec - z).max() < 1e-9 * np.abs(z).max()
    # centres every R/2 or R cells (0, step, ... up to the first one >= the side)
    g = radius // 2 if step == "half-radius" else radius
    assert d.step == g and d.n_atoms == (-(-90 // g) + 1) * (-(-77 // g) + 1)


def test_error_falls_with_sparsity_and_atoms():
    ex, target = fractal(128, 1), fractal(128, 2)
    p = GuerinParams(radius=8, factor=1, dictionary="complete")
    full = build_dictionary(ex, p, np.random.default_rng(0))
    order = np.random.default_rng(1).permutation(full.n_atoms)

    def sub(n):
        return type(full)(full.low[order[:n]], full.high[order[:n]], full.source[order[:n]], 8, 1)

    d = sub(64)
    errs_s = [np.sqrt(np.mean((synthesize(target, d, s, target.shape) - target) ** 2)) for s in (1, 2, 4, 8)]
    assert all(b < a for a, b in zip(errs_s, errs_s[1:])), errs_s
    errs_n = [np.sqrt(np.mean((synthesize(target, sub(n), 1, target.shape) - target) ** 2)) for n in (8, 64, 512)]
    assert all(b < a for a, b in zip(errs_n, errs_n[1:])), errs_n
    # per patch, OMP's residual never grows with s (the codes are least squares on their support)
    y = np.random.default_rng(3).normal(size=(50, d.low.shape[1]))
    res = [np.linalg.norm(y - sparse_codes(d.low, y, s) @ d.low, axis=1) for s in (1, 2, 4)]
    assert (res[1] <= res[0] + 1e-9).all() and (res[2] <= res[1] + 1e-9).all()


@pytest.mark.parametrize("kind", ["constrained", "complete"])
def test_constrained_atoms_are_real_patches(kind):
    ex = fractal(80, 4)
    p = GuerinParams(radius=8, factor=4, dictionary=kind, n_atoms=40, iterations=3)
    d = build_dictionary(ex, p, np.random.default_rng(0))
    assert 0 < d.n_atoms <= (40 if kind == "constrained" else 10**9)
    # every window of side 2R of the mirrored exemplar, zero-mean (independent of the primitives grid)
    from numpy.lib.stride_tricks import sliding_window_view

    win = sliding_window_view(np.pad(ex, 16, mode="symmetric"), (16, 16)).reshape(-1, 256)
    win = win - win.mean(axis=1, keepdims=True)
    win /= np.linalg.norm(win, axis=1, keepdims=True)
    atoms = d.high.reshape(d.n_atoms, -1)
    atoms = atoms / np.linalg.norm(atoms, axis=1, keepdims=True)
    best = (atoms @ win.T).max(axis=1)
    assert best.min() > 1 - 1e-9
    # the low atoms are the high atoms block-averaged, zero-mean, unit norm
    low = d.high.reshape(d.n_atoms, 4, 4, 4, 4).mean(axis=(2, 4)).reshape(d.n_atoms, -1)
    assert np.allclose(low, d.low) and np.allclose(np.linalg.norm(d.low, axis=1), 1.0)
    assert np.allclose(d.high.mean(axis=(1, 2)), 0.0, atol=1e-9)


def test_constrained_learning_lowers_the_coding_error():
    ex = fractal(128, 5)
    kw = dict(radius=8, factor=4, dictionary="constrained", n_atoms=16)
    signals = []
    from orokit.generators.guerin import primitives

    _, low, mean = primitives(ex, 8, 4)
    signals = low - mean[:, None]
    err = []
    for it in (0, 3):
        d = build_dictionary(ex, GuerinParams(iterations=it, **kw), np.random.default_rng(0))
        err.append(np.linalg.norm(signals - sparse_codes(d.low, signals, 1) @ d.low))
    assert err[1] < 0.97 * err[0], err


def test_ksvd_dictionary_keeps_pairs_and_codes():
    ex = fractal(96, 6)
    d = build_dictionary(ex, GuerinParams(radius=8, factor=4, dictionary="ksvd", n_atoms=24, iterations=2),
                         np.random.default_rng(0))
    assert d.n_atoms <= 24 and (d.source == -1).all()
    assert np.allclose(np.linalg.norm(d.low, axis=1), 1.0)
    # the low part of each joined atom is the block mean of its high part (K-SVD kept the pairs)
    low = d.high.reshape(d.n_atoms, 4, 4, 4, 4).mean(axis=(2, 4)).reshape(d.n_atoms, -1)
    assert np.corrcoef(low.ravel(), d.low.ravel())[0, 1] > 0.9


def test_atoms_with_more_detail_than_coarse_relief_are_dropped():
    """A nearly flat low patch carrying fine relief is not an atom (its 1 / norm scale blew up)."""
    ex = fractal(96, 8)
    rng = np.random.default_rng(0)
    ex[40:72, 40:72] = 1000.0 + 30.0 * rng.choice([-1.0, 1.0], size=(32, 32))  # block means nearly flat
    f, R = 4, 8
    keep = build_dictionary(ex, GuerinParams(radius=R, factor=f, max_detail=1.0), np.random.default_rng(0))
    every = build_dictionary(ex, GuerinParams(radius=R, factor=f, max_detail=float("inf")), np.random.default_rng(0))
    unresolved = build_dictionary(ex, GuerinParams(radius=R, factor=f), np.random.default_rng(0))  # NaN: every one
    assert unresolved.n_atoms == every.n_atoms

    def ratio(d):  # detail rms over the low patch's rms, both in the atom's own (normalised) scale
        up = np.repeat(np.repeat(d.high.reshape(-1, 2 * R // f, f, 2 * R // f, f).mean(axis=(2, 4)), f, 1), f, 2)
        return np.sqrt(np.mean((d.high - up) ** 2, axis=(1, 2))) / np.sqrt(np.mean(d.low ** 2, axis=1))

    assert ratio(keep).max() <= 1.0 + 1e-9
    assert ratio(every).max() > 3.0 and every.n_atoms > keep.n_atoms > 0
    # amplifying a rough coarse terrain (every low pattern occurs): the added detail stays bounded
    coarse = 1000.0 + 200.0 * np.random.default_rng(1).normal(size=(24, 24))
    tr = np.ones((coarse.shape[0] * f, coarse.shape[1] * f))
    def detail(d):  # the amplified terrain minus its own block means: the relief added below the coarse cell
        out = synthesize(coarse, d, 1, tr.shape)[2 * R:-2 * R, 2 * R:-2 * R]
        return np.abs(out - np.kron(block_mean(out, f), np.ones((f, f)))).max()

    dev = {k: detail(d) for k, d in (("keep", keep), ("every", every))}
    assert dev["keep"] < 0.5 * dev["every"], dev


def test_max_detail_follows_the_coarse_source():
    """NaN: 1 on the tree's coarse terrain, every primitive (inf) on a coarse DEM; recorded as derived."""
    import json

    import xarray as xr

    from orokit.generators.guerin import TREE_MAX_DETAIL, resolve_max_detail

    assert resolve_max_detail(GuerinParams(max_detail=2.0), coarse_dem=False).max_detail == 2.0
    exemplar = xr.DataArray(fractal(160, 7), dims=("y", "x"), attrs={"cell_size_m": 50.0})
    dem = render_terrain(small_tree(), generator="guerin", cell_size_m=50.0, exemplar=exemplar, seed=0,
                         params={"radius": 8, "factor": 4})
    assert json.loads(dem.attrs["derived"])["max_detail"] == TREE_MAX_DETAIL == 1.0
    coarse = dem.copy(data=np.asarray(dem.values))
    amp = render_terrain(small_tree(), generator="guerin", cell_size_m=50.0, exemplar=exemplar, seed=0,
                         params={"radius": 8, "factor": 4}, inputs={"coarse": coarse})
    assert json.loads(amp.attrs["derived"])["max_detail"] == "inf"


@pytest.mark.realdata
@pytest.mark.slow
def test_8x_amplification_beats_bicubic(real_data):
    """Held-out halves of a real DEM: the exemplar's patches restore the fine slopes that bicubic loses."""
    from scipy.ndimage import map_coordinates
    from scipy.stats import wasserstein_distance

    from orokit.io.manifest import load_manifest
    from orokit.io.dem import read_dem

    ds = load_manifest()["norway"]
    z = read_dem(real_data("norway"), z_units=ds.z_units, cell_size_m=ds.cell_size_m).values.astype(float)
    ex, truth = z[:, :320], z[:, 328:648]  # disjoint halves
    coarse = block_mean(truth, 8)
    truth = truth[: coarse.shape[0] * 8, : coarse.shape[1] * 8]
    p = GuerinParams()  # R = 8, factor 8, s = 1, complete dictionary, every primitive (max_detail NaN: the paper)
    amp = synthesize(coarse, build_dictionary(ex, p, np.random.default_rng(0)), 1, truth.shape)
    tr, tc = ((np.arange(n) + 0.5) / 8 - 0.5 for n in truth.shape)
    bic = map_coordinates(coarse, np.meshgrid(tr, tc, indexing="ij"), order=3, mode="nearest")
    assert bic.shape == amp.shape == truth.shape

    def slope(a):
        gy, gx = np.gradient(a, ds.cell_size_m)
        return np.degrees(np.arctan(np.hypot(gx, gy))).ravel()

    w_amp = wasserstein_distance(slope(amp), slope(truth))
    w_bic = wasserstein_distance(slope(bic), slope(truth))
    # measured (norway, R = 8): 3.77 deg against bicubic's 4.21 (mean slopes 19.6 / 19.1, truth 22.6)
    assert w_amp < 0.95 * w_bic, (w_amp, w_bic)
    # the coarse shape is kept: block means of the amplified terrain stay near the coarse input
    assert np.sqrt(np.mean((block_mean(amp, 8) - coarse) ** 2)) < 0.5 * truth.std()


def test_render_from_a_tree_follows_the_coarse_relief():
    tree = small_tree()
    ex = fractal(160, 7)
    import xarray as xr

    exemplar = xr.DataArray(ex, dims=("y", "x"), attrs={"cell_size_m": 50.0})
    dem = render_terrain(tree, generator="guerin", cell_size_m=50.0, exemplar=exemplar, seed=0,
                         params={"radius": 8, "factor": 4})
    assert dem.shape == (160, 160) and np.isfinite(dem.values).all()
    z = dem.values
    x0, y0 = dem.rio.transform().c, dem.rio.transform().f
    at = {i: z[int((y0 - y) // 50.0), int((x - x0) // 50.0)] for i, (x, y) in
          enumerate(tree.peaks[["x", "y"]].to_numpy())}
    # the highest peak's area stays higher than the lowest peak's (coarse relief survives amplification)
    assert at[0] > at[4]
    again = render_terrain(tree, generator="guerin", cell_size_m=50.0, exemplar=exemplar, seed=0,
                           params={"radius": 8, "factor": 4})
    assert again.values.tobytes() == dem.values.tobytes()


@pytest.mark.parametrize("kind", ["complete", "constrained"])
def test_a_learned_dictionary_passed_in_gives_the_same_raster(kind):
    """`learn` + `inputs={"learned": ...}` (the benchmark's cached learning) renders the same bytes."""
    import xarray as xr

    from orokit.generators.guerin import learn
    from orokit.raster.rasterize import make_grid

    tree = small_tree()
    exemplar = xr.DataArray(fractal(160, 7), dims=("y", "x"), attrs={"cell_size_m": 50.0})
    p = GuerinParams(radius=8, factor=4, dictionary=kind, n_atoms=64, iterations=1)
    grid = make_grid((0.0, 0.0, 8000.0, 8000.0), 50.0)
    direct = render_terrain(tree, generator="guerin", grid=grid, exemplar=exemplar, seed=3, params=p)
    d = learn(exemplar, grid, p, np.random.default_rng(3))
    cached = render_terrain(tree, generator="guerin", grid=grid, exemplar=exemplar, seed=3, params=p,
                            inputs={"learned": d})
    assert cached.values.tobytes() == direct.values.tobytes()
    assert "dictionary" in direct.attrs["timings"] and "dictionary" not in cached.attrs["timings"]
    for other in (GuerinParams(radius=16, factor=4), GuerinParams(radius=8, factor=4, step="radius")):
        with pytest.raises(InputError, match="learn it again"):
            render_terrain(tree, generator="guerin", grid=grid, exemplar=exemplar, seed=3, params=other,
                           inputs={"learned": d})


@pytest.mark.parametrize("kv, msg", [
    ({"radius": 7}, "radius must be an even"), ({"radius": 16, "factor": 3}, "must divide"),
    ({"sparsity": 0}, "sparsity must be"), ({"radius": 4, "factor": 8}, "at least 2 cells"),
    ({"sparsity": 5, "radius": 8, "factor": 8}, "exceeds the coarse patch"), ({"n_atoms": 0}, "n_atoms"),
    ({"dictionary": "pca"}, "not one of"), ({"iterations": -1}, "iterations"), ({"step": "quarter"}, "not one of"),
    ({"max_detail": -1.0}, "max_detail"),
])
def test_out_of_range_parameters_are_refused(kv, msg):
    with pytest.raises(InputError, match=msg):
        GuerinParams(**kv)


def test_missing_or_useless_exemplar_is_refused():
    import xarray as xr

    with pytest.raises(InputError, match="needs an exemplar"):
        render_terrain(small_tree(), generator="guerin", cell_size_m=100.0, seed=0)
    tiny = xr.DataArray(np.ones((10, 10)), dims=("y", "x"), attrs={"cell_size_m": 100.0})
    with pytest.raises(InputError, match="smaller than one patch"):
        render_terrain(small_tree(), generator="guerin", cell_size_m=100.0, seed=0, exemplar=tiny)
    flat = xr.DataArray(np.full((80, 80), 5.0), dims=("y", "x"), attrs={"cell_size_m": 100.0})
    with pytest.raises(InputError, match="no usable patch"):
        render_terrain(small_tree(), generator="guerin", cell_size_m=100.0, seed=0, exemplar=flat)
    with pytest.raises(InputError, match="caller reads"):
        render_terrain(small_tree(), generator="guerin", cell_size_m=100.0, seed=0, exemplar=flat,
                       params=["coarse=x.tif"])


def test_cli_render_guerin_amplifies_a_coarse_dem_file(tmp_path):
    """`--param coarse=DEM` amplifies that DEM (tree only gives the grid); tags hash both inputs."""
    import json

    import rasterio
    from click.testing import CliRunner

    from orokit.cli.main import cli
    from orokit.generators.base import as_dataarray
    from orokit.io.divide_tree_io import write_divide_tree_gpkg
    from orokit.io.raster_io import write_cog
    from orokit.raster.rasterize import make_grid

    write_divide_tree_gpkg(small_tree(crs="EPSG:32633"), tmp_path / "tree.gpkg")
    ex = fractal(160, 8)
    write_cog(as_dataarray(ex, make_grid((0.0, 0.0, 8000.0, 8000.0), 50.0), "EPSG:32633"), tmp_path / "ex.tif")
    coarse = 2000.0 + 0.2 * np.add.outer(np.arange(20) * 400.0, np.arange(20) * 100.0)  # a tilted plane, 400 m cells
    write_cog(as_dataarray(coarse, make_grid((0.0, 0.0, 8000.0, 8000.0), 400.0), "EPSG:32633"), tmp_path / "c.tif")
    out = tmp_path / "dem.tif"
    args = ["render", str(tmp_path / "tree.gpkg"), "-o", str(out), "--resolution", "50m", "--generator", "guerin",
            "--exemplar", str(tmp_path / "ex.tif"), "--param", f"coarse={tmp_path / 'c.tif'}", "--param", "radius=8",
            "--seed", "1"]
    r = CliRunner().invoke(cli, args)
    assert r.exit_code == 0, r.output
    with rasterio.open(out) as src:
        z = src.read(1).astype(float)
        tags = src.tags()
    assert tags["generator"] == "guerin" and len(tags["coarse_sha256"]) == 64 and len(tags["exemplar_sha256"]) == 64
    assert json.loads(tags["parameters"])["coarse"].endswith("c.tif")
    # the amplified terrain keeps the coarse plane: 400 m block means within a few metres of it (away from borders)
    means = block_mean(z, 8)
    assert np.abs(means[2:-2, 2:-2] - coarse[2:-2, 2:-2]).max() < 0.05 * np.ptp(coarse)
    assert z.std() > 0 and np.abs(z - np.kron(coarse, np.ones((8, 8)))).max() > 1.0  # detail was added
    bad_args = args[:3] + [str(tmp_path / "bad.tif")] + args[4:-4] + ["--param", "coarse=nope.tif", "--seed", "1"]
    bad = CliRunner().invoke(cli, bad_args)
    assert not (tmp_path / "bad.tif").exists()
    assert bad.exit_code != 0 and "coarse=nope.tif" in bad.output and "Traceback" not in bad.output
