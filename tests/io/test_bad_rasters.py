"""Rasters that would silently give wrong terrain are refused or reported (issue 15)."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
import rasterio
from click.testing import CliRunner
from rasterio.transform import Affine

from orokit.cli.main import cli
from orokit.errors import CRSError, InputError, OrokitWarning, UnitsError
from orokit.io.dem import read_dem

FLT_MAX = float(np.finfo(np.float32).max)


def _tif(path, z, *, crs="EPSG:32633", transform=Affine(30, 0, 500000, 0, -30, 4000000), nodata=None):
    z = np.asarray(z)
    with rasterio.open(path, "w", driver="GTiff", width=z.shape[1], height=z.shape[0], count=1, dtype=z.dtype,
                       crs=crs, transform=transform, nodata=nodata) as dst:
        dst.write(z, 1)
    return path


def _asc(path, rows, *, ncols, nrows):
    head = f"ncols {ncols}\nnrows {nrows}\nxllcorner 0\nyllcorner 0\ncellsize 30\n"
    path.write_text(head + "\n".join(" ".join(str(v) for v in r) for r in rows) + "\n")
    return path


def test_ascii_grid_with_wide_rows_is_refused(tmp_path):
    rows = [[1, 2, 3, 4], [5, 6, 7, 8, 9], [9, 8, 7, 6]]
    p = _asc(tmp_path / "wide.asc", rows, ncols=4, nrows=3)
    with pytest.raises(InputError, match=r"wide.asc: data row 2 holds 5 values but the header says ncols 4"):
        read_dem(p, z_units="m", cell_size_m=30)
    res = CliRunner().invoke(cli, ["analyze", str(p), "-o", str(tmp_path / "o"), "--z-units", "m"])
    assert res.exit_code == 1 and "ncols 4" in res.output and "Traceback" not in res.output
    assert not (tmp_path / "o").exists()


def test_ascii_grid_with_missing_rows_is_refused_and_a_good_one_reads(tmp_path):
    p = _asc(tmp_path / "short.asc", [[1, 2, 3], [4, 5, 6]], ncols=3, nrows=3)
    with pytest.raises(InputError, match=r"2 data rows but the header says nrows 3|cannot read"):
        read_dem(p, z_units="m")
    good = _asc(tmp_path / "good.asc", [[1, 2, 3], [4, 5, 6]], ncols=3, nrows=2)
    dem = read_dem(good, z_units="m")
    assert dem.values.tolist() == [[1, 2, 3], [4, 5, 6]]


@pytest.mark.parametrize("void", [-FLT_MAX, -3.4e38, -3.402823e38, FLT_MAX])
def test_untagged_float32_void_markers_become_nodata_with_a_warning(tmp_path, void):
    z = np.full((6, 7), 1200.0, dtype="float32")
    z[2:4, 3:5] = void
    p = _tif(tmp_path / "v.tif", z)
    with pytest.warns(OrokitWarning, match=r"v.tif: 4 cells hold void markers or values beyond any elevation"):
        dem = read_dem(p)
    assert int(np.isnan(dem.values).sum()) == 4 and float(np.nanmax(dem.values)) == 1200.0


def test_tagged_void_marker_is_silent_nodata(tmp_path):
    z = np.full((5, 5), 800.0, dtype="float32")
    z[0, 0] = -FLT_MAX
    p = _tif(tmp_path / "t.tif", z, nodata=-FLT_MAX)
    with warnings.catch_warnings():
        warnings.simplefilter("error", OrokitWarning)
        dem = read_dem(p)
    assert int(np.isnan(dem.values).sum()) == 1


@pytest.mark.parametrize("sentinel, dtype", [(-9999, "float32"), (-32768, "int16"), (-9999, "int16")])
def test_untagged_integer_void_blocks_are_reported_not_terrain(tmp_path, sentinel, dtype):
    z = np.full((8, 8), 500, dtype=dtype)
    z[:3, :3] = sentinel
    p = _tif(tmp_path / "b.tif", z)
    with pytest.warns(OrokitWarning, match=f"9 cells hold void markers.*{sentinel}"):
        dem = read_dem(p)
    assert int(np.isnan(dem.values).sum()) == 9
    # the chunked reader masks them too
    with pytest.warns(OrokitWarning):
        lazy = read_dem(p, chunks=4).values
    assert np.array_equal(np.isnan(lazy), np.isnan(dem.values))


def test_values_beyond_plausible_after_unit_conversion(tmp_path):
    z = np.array([[1000.0, 29000.0], [31000.0, 500.0]], dtype="float32")  # feet: 8839 m ok, 9449 m not
    p = _tif(tmp_path / "ft.tif", z)
    with pytest.warns(OrokitWarning, match="1 cells"):
        dem = read_dem(p, z_units="ft")
    assert np.isnan(dem.values[1, 0]) and dem.values[0, 1] == pytest.approx(29000 * 0.3048)


def test_latitude_beyond_90_is_refused(tmp_path):
    z = np.full((10, 10), 100.0, dtype="float32")
    p = _tif(tmp_path / "pole.tif", z, crs="EPSG:4326", transform=Affine(0.01, 0, 10.0, 0, -0.01, 90.1))
    with pytest.raises(CRSError, match=r"pole.tif reaches latitude 90.1 degrees"):
        read_dem(p)
    res = CliRunner().invoke(cli, ["analyze", str(p), "-o", str(tmp_path / "o")])
    assert res.exit_code == 1 and "latitude 90.1" in res.output and "Traceback" not in res.output
    ok = _tif(tmp_path / "ok.tif", z, crs="EPSG:4326", transform=Affine(0.01, 0, 10.0, 0, -0.01, 90.0))
    assert read_dem(ok).shape == (10, 10)  # a grid touching the pole is fine


def test_hgt_of_the_wrong_size_says_expected_and_actual(tmp_path):
    p = tmp_path / "N46E007.hgt"
    p.write_bytes(b"\0" * (2 * 1201 * 1201 - 100))
    with pytest.raises(InputError, match=r"2,884,702 bytes, expected 2,884,802 bytes \(1201 x 1201 samples\)"):
        read_dem(p)


def test_a_dem_in_feet_without_units_is_refused_naming_the_fix(tmp_path):
    """A georeferenced DEM in feet that declares no units was read as metres with every cell above 9000 "m"
    made nodata (a warning, then an analysis of what was left: 50 of 720 peaks on himalaya-everest's feet): a range
    of such values is no void marker, so it is refused, in memory and chunked; --z-units ft reads it, --z-units m
    keeps the old reading (a warning), a few void markers above 9000 still only warn."""
    rng = np.random.default_rng(0)
    z = (rng.uniform(7000.0, 29000.0, (40, 50))).astype("float32")  # feet, as the PNG datasets
    p = _tif(tmp_path / "ft.tif", z)
    for chunks in (None, 16):
        with pytest.raises(UnitsError, match=r"ft.tif declares no elevation units.*not the metre.*--z-units ft"):
            read_dem(p, chunks=chunks)
    res = CliRunner().invoke(cli, ["analyze", str(p), "-o", str(tmp_path / "o"), "--no-progress"])
    assert res.exit_code == 1 and "--z-units ft" in res.output and "Traceback" not in res.output
    assert not (tmp_path / "o").exists()
    assert float(np.nanmax(read_dem(p, z_units="ft").values)) == pytest.approx(float(z.max()) * 0.3048, rel=1e-6)
    with pytest.warns(OrokitWarning, match="void markers"):
        assert np.isnan(read_dem(p, z_units="m").values).any()
    few = np.full((10, 10), 1500.0, dtype="float32")
    few[0, :3] = (9999.0, 32767.0, 65535.0)
    with pytest.warns(OrokitWarning, match="3 cells hold void markers"):
        read_dem(_tif(tmp_path / "few.tif", few))
