"""Rendered rasters on disk: readable by read_dem without flags, seed recorded, engine kernels reused."""
from __future__ import annotations

import numpy as np
import pytest
import rasterio
from click.testing import CliRunner

import orokit
import orokit.raster._kernels as raster_kernels
import orokit.topology._kernels as engine_kernels
from orokit.cli.main import cli
from orokit.io.dem import read_dem
from orokit.io.raster_io import write_cog, write_hillshade_png
from orokit.raster.params import RenderParams
from orokit.raster.render import render_elevation, resolve_seed
from orokit.topology.divide_tree import DivideTree
from orokit.validate.roundtrip import compare_peaks

FAST = RenderParams(erosion_steps=1)


def two_peaks(crs=None, x0: float = 0.0, y0: float = 0.0) -> DivideTree:
    """Peaks of 600 m and 550 m, 2 km apart, joined through a 450 m saddle (prominence 100 m)."""
    return DivideTree.from_arrays([[x0 + 1000.0, y0 + 1000.0, 600.0], [x0 + 3000.0, y0 + 1000.0, 550.0]],
                                  [[x0 + 2000.0, y0 + 1000.0, 450.0]], [[0, 1, 0]], crs=crs,
                                  attrs={"extent": [x0, y0, x0 + 4000.0, y0 + 2000.0]})


def test_cog_without_crs_reads_back_as_metres_on_its_grid(tmp_path):
    tree = two_peaks()
    dem = render_elevation(tree, cell_size_m=50.0, erosion=False, params=FAST, rng=1)
    path = tmp_path / "dem.tif"
    write_cog(dem, path)
    back = read_dem(str(path))  # no z_units, no cell_size_m
    assert back.attrs["z_units_in"] == "m" and not back.attrs["z_units_assumed"]
    assert back.attrs["local_grid"] and back.rio.crs is None
    assert back.rio.transform() == dem.rio.transform()
    np.testing.assert_array_equal(back.values, dem.values)
    with rasterio.open(path) as src:
        assert src.units == ("m",)
    # the round trip through the file: peaks at the tree's coordinates with its prominences
    res = orokit.analyze(back, min_prominence_m=30.0, isolation=False)
    comp = compare_peaks(tree, res.peaks, min_prominence_m=30.0, distance_tol_m=100.0)
    assert comp.recovered_share == 1.0 and len(comp.extra) == 0


def test_cog_keeps_the_tree_crs_and_declares_metres(tmp_path):
    tree = two_peaks(crs="EPSG:32633", x0=500_000.0, y0=4_000_000.0)
    dem = render_elevation(tree, cell_size_m=100.0, erosion=False, params=FAST, rng=2)
    write_cog(dem, tmp_path / "dem.tif")
    back = read_dem(str(tmp_path / "dem.tif"))
    assert back.rio.crs.to_epsg() == 32633 and not back.attrs["local_grid"]
    assert not back.attrs["z_units_assumed"]  # declared by the band, not guessed from the CRS
    assert back.rio.transform().c == 500_000.0


def test_cli_analyze_reads_a_rendered_raster(tmp_path):
    tree = two_peaks()
    write_cog(render_elevation(tree, cell_size_m=50.0, erosion=False, params=FAST, rng=3), tmp_path / "dem.tif")
    r = CliRunner().invoke(cli, ["analyze", str(tmp_path / "dem.tif"), "-o", str(tmp_path / "a"),
                                 "--min-prominence", "30"])
    assert r.exit_code == 0, r.output
    assert (tmp_path / "a" / "analysis.json").is_file()


def test_seed_is_recorded_and_replays_the_raster():
    tree = two_peaks()
    kw = dict(cell_size_m=100.0, erosion=False, params=FAST)
    fresh = render_elevation(tree, **kw, rng=None)
    seed = fresh.attrs["seed"]
    assert isinstance(seed, int) and seed >= 0
    np.testing.assert_array_equal(render_elevation(tree, **kw, rng=seed).values, fresh.values)
    # a Generator or a SeedSequence also yields a recorded int that replays the raster
    for rng in (np.random.default_rng(5), np.random.SeedSequence(5).spawn(2)[1]):
        out = render_elevation(tree, **kw, rng=rng)
        assert out.attrs["seed"] >= 0
        np.testing.assert_array_equal(render_elevation(tree, **kw, rng=out.attrs["seed"]).values, out.values)
    assert render_elevation(tree, **kw, rng=9).attrs["seed"] == 9


def test_resolve_seed():
    assert resolve_seed(0) == 0 and resolve_seed(np.int64(12)) == 12
    assert resolve_seed(None) != resolve_seed(None)  # fresh entropy each time
    assert resolve_seed(np.random.SeedSequence(3)) == resolve_seed(np.random.SeedSequence(3))
    with pytest.raises(orokit.errors.InputError, match="non-negative"):
        resolve_seed(-1)
    with pytest.raises(orokit.errors.InputError, match="rng must be"):
        resolve_seed("7")


def test_cli_render_without_seed_records_a_replayable_seed(tmp_path):
    from orokit.io.divide_tree_io import write_divide_tree_gpkg

    gpkg = tmp_path / "tree.gpkg"
    write_divide_tree_gpkg(two_peaks(), gpkg)
    base = ["render", str(gpkg), "--resolution", "100m", "--no-erosion", "--extent", "0", "0", "4000", "2000"]
    r = CliRunner().invoke(cli, base + ["-o", str(tmp_path / "a.tif")])
    assert r.exit_code == 0, r.output
    with rasterio.open(tmp_path / "a.tif") as src:
        seed = int(src.tags()["seed"])
        a = src.read(1)
    assert seed >= 0 and f"seed {seed}" in r.output
    r = CliRunner().invoke(cli, base + ["-o", str(tmp_path / "b.tif"), "--seed", str(seed)])
    assert r.exit_code == 0, r.output
    with rasterio.open(tmp_path / "b.tif") as src:
        np.testing.assert_array_equal(src.read(1), a)


@pytest.mark.parametrize("bad", ["1.2.3km", ".", "-5m", "0m", "nan"])
def test_cli_render_refuses_malformed_lengths(tmp_path, bad):
    from orokit.io.divide_tree_io import write_divide_tree_gpkg

    gpkg = tmp_path / "tree.gpkg"
    write_divide_tree_gpkg(two_peaks(), gpkg)
    for opt in ("--resolution", "--lambda"):
        r = CliRunner().invoke(cli, ["render", str(gpkg), "-o", str(tmp_path / "x.tif"), opt, bad])
        assert r.exit_code == 2 and opt in r.output, r.output
        assert not (tmp_path / "x.tif").exists()


def test_basins_come_from_the_engine_kernels(monkeypatch):
    """cap_basins labels the raster's basins with the orometry engine's kernels, not a copy."""
    from orokit.raster import enforce

    assert not hasattr(raster_kernels, "basin_labels")
    assert enforce.ascent_labels is engine_kernels.ascent_labels  # the engine's kernel itself
    calls = []
    real = engine_kernels.ascent_labels

    def counting(z, label, ptr=None):
        calls.append(z.size)
        return real(z, label, ptr)

    monkeypatch.setattr(enforce, "ascent_labels", counting)
    dem = render_elevation(two_peaks(), cell_size_m=100.0, erosion=False, params=FAST, rng=4)
    assert calls and calls[0] == dem.size


def test_hillshade_preview_uses_the_shared_hillshade(tmp_path, monkeypatch):
    import orokit.io.raster_io as raster_io
    import orokit.reports.dem_summary as dem_summary
    import orokit.raster.shade as shade

    assert raster_io.hillshade is shade.hillshade is dem_summary.hillshade  # one shading for previews and reports
    from PIL import Image

    calls = []
    real = shade.hillshade

    def counting(dem, **kw):
        calls.append(dem.shape)
        return real(dem, **kw)

    monkeypatch.setattr(raster_io, "hillshade", counting)
    dem = render_elevation(two_peaks(), cell_size_m=50.0, erosion=False, params=FAST, rng=4)
    dem[:5, :5] = np.nan
    write_hillshade_png(dem, tmp_path / "hs.png", max_size=30)
    img = np.asarray(Image.open(tmp_path / "hs.png"))
    assert calls == [img.shape] and max(img.shape) <= 30  # 80 x 40 cells, every 3rd
    assert img[0, 0] == 0 and img.max() > 0  # NaN cells are black


def test_render_like_takes_the_cell_size_and_extent_of_the_like_raster(tmp_path, make_dem):
    """`render --like DEM` without --resolution renders on the DEM's own grid (extent and cells)."""
    from orokit.io.divide_tree_io import write_divide_tree_gpkg

    gpkg = tmp_path / "tree.gpkg"
    write_divide_tree_gpkg(two_peaks(crs="EPSG:32633", x0=500_000.0, y0=4_000_000.0), gpkg)
    like = make_dem(np.zeros((25, 45), np.float32), res=100.0, crs="EPSG:32633", origin=(499_800.0, 4_002_200.0))
    like_path = tmp_path / "like.tif"
    like.attrs["units"] = "m"
    write_cog(like, like_path)
    out = tmp_path / "x.tif"
    r = CliRunner().invoke(cli, ["render", str(gpkg), "-o", str(out), "--like", str(like_path), "--no-erosion",
                                 "--seed", "1"])
    assert r.exit_code == 0, r.output
    back = read_dem(str(out))
    assert back.shape == like.shape
    assert tuple(back.rio.transform())[:6] == pytest.approx(tuple(like.rio.transform())[:6])
    assert back.rio.crs == like.rio.crs
    r = CliRunner().invoke(cli, ["render", str(gpkg), "-o", str(tmp_path / "y.tif"), "--like", "no-such-dataset"])
    assert r.exit_code != 0 and "--like" in r.output and "no-such-dataset" in r.output


#: ``orokit render`` in a process of its own (as the console script runs it), then the collector's state
_OWN_PROCESS = """
import gc, sys
from orokit.cli import main as m
m._CONSOLE["process"] = True
m.cli.main(["render", sys.argv[1], "-o", sys.argv[2], "--resolution", "100m", "--no-erosion", "--seed", "3",
            "--extent", "0", "0", "4000", "2000", "--no-progress"], standalone_mode=False)
print(gc.isenabled(), gc.get_freeze_count())
"""


def test_cli_render_freezes_the_loaded_modules_out_of_the_collector_in_its_own_process_only(tmp_path):
    """In orokit's own process the objects alive once the modules are loaded and the tree read are frozen
    out of the collector (and collection is on again); a caller's process (CliRunner) is left as it was;
    the raster is the same."""
    import gc
    import subprocess
    import sys

    from orokit.io.divide_tree_io import write_divide_tree_gpkg

    gpkg = tmp_path / "tree.gpkg"
    write_divide_tree_gpkg(two_peaks(), gpkg)
    res = subprocess.run([sys.executable, "-c", _OWN_PROCESS, str(gpkg), str(tmp_path / "own.tif")],
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    enabled, frozen = res.stdout.split()[-2:]
    assert enabled == "True" and int(frozen) > 10_000  # the modules' objects (~150 k in a full render)
    before = (gc.isenabled(), gc.get_freeze_count())
    r = CliRunner().invoke(cli, ["render", str(gpkg), "-o", str(tmp_path / "runner.tif"), "--resolution", "100m",
                                 "--no-erosion", "--seed", "3", "--extent", "0", "0", "4000", "2000"])
    assert r.exit_code == 0, r.output
    assert (gc.isenabled(), gc.get_freeze_count()) == before
    with rasterio.open(tmp_path / "own.tif") as a, rasterio.open(tmp_path / "runner.tif") as b:
        assert a.read(1).tobytes() == b.read(1).tobytes()
