"""A DEM or tree in a projected CRS whose unit is not the metre (US survey feet): cell sizes are recorded in
metres, and what takes the coordinates for metres (the renderer, the generators, ``--like``) refuses it."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
import rasterio
from click.testing import CliRunner
from rasterio.transform import from_origin

from orokit.errors import CRSError
from tests.helpers.trees import small_tree

FOOT_US = 1200.0 / 3937.0  # metres per US survey foot


def _ft_tif(path, crs="EPSG:2227"):
    z = np.add.outer(np.sin(np.arange(40) / 4.0), np.cos(np.arange(50) / 5.0)).astype(np.float32) * 300.0 + 1000.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with rasterio.open(path, "w", driver="GTiff", width=50, height=40, count=1, dtype="float32", crs=crs,
                           transform=from_origin(6_000_000.0, 2_000_000.0, 100.0, 100.0)) as dst:
            dst.write(z[None])
    return str(path)


def test_a_feet_dems_cell_size_is_recorded_in_metres(tmp_path):
    """Before: 100 (the CRS's feet) under ``cell_size_m``, in the DEM's attrs and the analysis's."""
    from orokit import analyze
    from orokit.io.dem import read_dem

    path = _ft_tif(tmp_path / "ft.tif")
    assert read_dem(path).attrs["cell_size_m"] == pytest.approx((100 * FOOT_US, 100 * FOOT_US), rel=1e-12)
    result = analyze(path, min_prominence_m=10.0, isolation=False)
    assert result.attrs["cell_size_m"] == pytest.approx([100 * FOOT_US, 100 * FOOT_US], rel=1e-12)
    metric = read_dem(_ft_tif(tmp_path / "m.tif", crs="EPSG:32633")).attrs["cell_size_m"]
    assert metric == (100.0, 100.0)  # a metric CRS: the transform's own numbers


def test_rendering_a_tree_in_feet_is_refused():
    """Before: the tree's feet were taken for metres (a raster 3.28 times too wide, labelled with the feet CRS)."""
    from orokit.raster.render import render_elevation

    with pytest.raises(CRSError, match=r"US survey foot.*reproject"):
        render_elevation(small_tree(crs="EPSG:2227"), cell_size_m=200.0, erosion=False, rng=0)
    from orokit.generators.base import check_crs

    with pytest.raises(CRSError, match="geographic"):
        check_crs(small_tree(crs="EPSG:4326"))
    assert check_crs(small_tree(crs="EPSG:32633")).to_epsg() == 32633


def test_render_like_a_feet_raster_is_refused(tmp_path):
    """``--like`` gives the render its cell size in metres (before: 100 ft rendered as '100 m' cells)."""
    from orokit.cli.main import cli
    from orokit.io.divide_tree_io import write_divide_tree_gpkg

    tree = tmp_path / "tree.gpkg"
    write_divide_tree_gpkg(small_tree(crs="EPSG:32633"), tree)
    like = _ft_tif(tmp_path / "ft.tif")
    out = tmp_path / "r.tif"
    res = CliRunner().invoke(cli, ["render", str(tree), "--like", like, "-o", str(out), "--no-erosion", "--seed", "0",
                                   "--no-progress"])
    assert res.exit_code == 2, res.output
    assert "ft.tif" in res.output and "US survey foot" in res.output and not out.exists()


def test_a_feet_trees_area_is_in_square_kilometres():
    """``orokit type`` of a tree file: its area from the peaks' extent (before: square feet taken for m2)."""
    from orokit.cli.type_cmd import _tree_area_km2

    from pyproj import CRS

    metres, feet = small_tree(crs=CRS.from_epsg(32633)), small_tree(crs=CRS.from_epsg(2227))
    assert _tree_area_km2(feet) == pytest.approx(_tree_area_km2(metres) * FOOT_US**2, rel=1e-9)
