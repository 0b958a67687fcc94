"""read_dem_array: the in-memory reader without xarray gives what read_dem gives."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
import rasterio
from rasterio.transform import Affine

from orokit.errors import InputError
from orokit.io.dem import DemArray, read_dem, read_dem_array


def _write(path, z, *, crs="EPSG:32633", transform=Affine(30, 0, 500000, 0, -30, 4000000), nodata=None,
           unit=None):
    with rasterio.open(path, "w", driver="GTiff", width=z.shape[1], height=z.shape[0], count=1, dtype=z.dtype,
                       crs=crs, transform=transform, nodata=nodata) as ds:
        ds.write(z, 1)
        if unit:
            ds.set_band_unit(1, unit)
    return path


def _cases(tmp_path):
    rng = np.random.default_rng(7)
    z16 = rng.integers(0, 3000, (37, 53)).astype(np.int16)
    z16[3, 4] = -32768
    z32 = rng.normal(1000.0, 300.0, (41, 29)).astype(np.float32)
    z32[0, 0] = np.nan
    return {
        "int16 nodata": _write(tmp_path / "a.tif", z16, nodata=-32768),
        "float32 feet": _write(tmp_path / "b.tif", z32, unit="ft"),
        "geographic": _write(tmp_path / "c.tif", z32, crs="EPSG:4326",
                             transform=Affine(1 / 3600, 0, 7.0, 0, -1 / 3600, 46.0)),
        "local grid": _write(tmp_path / "d.tif", z32, crs=None, transform=Affine(5, 0, 0, 0, -5, 0), unit="m"),
    }


@pytest.mark.parametrize("case", ["int16 nodata", "float32 feet", "geographic", "local grid"])
def test_same_pixels_georeference_and_attrs_as_read_dem(tmp_path, case):
    path = _cases(tmp_path)[case]
    da = read_dem(path)
    arr = read_dem_array(path)
    assert isinstance(arr, DemArray)
    assert arr.values.dtype == np.float32 and arr.shape == da.shape and arr.dims == da.dims
    np.testing.assert_array_equal(arr.values, da.values)  # NaN == NaN here
    assert arr.transform == da.rio.transform()
    assert (arr.crs is None) == (da.rio.crs is None)
    if arr.crs is not None:
        assert arr.crs.equals(da.rio.crs)
    assert arr.attrs == {k: v for k, v in da.attrs.items() if k != "_FillValue"}  # rioxarray's nodata marker


def test_bad_input_is_the_same_error(tmp_path):
    with pytest.raises(InputError, match="not found"):
        read_dem_array(tmp_path / "missing.tif")
    z = np.full((4, 4), -32768, np.int16)
    path = _write(tmp_path / "void.tif", z, nodata=-32768)
    with pytest.raises(InputError, match="no valid cells"):
        read_dem_array(path)


def test_analyze_a_dem_array_gives_the_tables_of_the_data_array(tmp_path):
    import orokit

    path = _cases(tmp_path)["int16 nodata"]
    a = orokit.analyze(read_dem(path), min_prominence_m=0.0)
    b = orokit.analyze(read_dem_array(path), min_prominence_m=0.0)
    assert len(a.peaks) > 5
    assert a.peaks.drop(columns="geometry").equals(b.peaks.drop(columns="geometry"))
    assert a.saddles.drop(columns="geometry").equals(b.saddles.drop(columns="geometry"))
    assert {k: v for k, v in a.attrs.items() if k != "timings_s"} == {k: v for k, v in b.attrs.items()
                                                                      if k != "timings_s"}


def test_cli_in_memory_analysis_imports_neither_xarray_nor_dask(tmp_path):
    """`orokit analyze` in memory reads with rasterio only: no xarray/rioxarray/dask start-up cost (nor
    scipy.linalg, which numba imports only for a BLAS no kernel uses)."""
    path = _cases(tmp_path)["float32 feet"]
    code = (
        "import json, sys\n"
        "from orokit.cli.main import cli\n"
        f"cli(['-q', 'analyze', {str(path)!r}, '-o', {str(tmp_path / 'out')!r}, '--no-progress'],"
        " standalone_mode=False)\n"
        "print(json.dumps(sorted(m for m in ('xarray', 'rioxarray', 'dask', 'dask.array', 'scipy.linalg')"
        " if m in sys.modules)))\n"
        "import scipy.linalg\n"  # numba's BLAS probe was skipped (see cli.analyze), scipy.linalg still imports
        "print(scipy.linalg.solve([[2.0]], [4.0])[0])\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    lines = res.stdout.strip().splitlines()
    assert json.loads(lines[-2]) == [] and float(lines[-1]) == 2.0
    assert (tmp_path / "out" / "analysis.json").exists()


@pytest.mark.parametrize("dtype", ["int16", "float32"])
def test_whole_raster_read_in_parallel_stripes_is_the_plain_read(tmp_path, monkeypatch, dtype):
    """The whole-raster read (row stripes in threads, one GDAL handle each, starting on block rows) gives
    rasterio's pixels, converted as one read would, and one warning with the count of all stripes."""
    import warnings

    import orokit.io.dem as dem_mod
    from orokit.errors import OrokitWarning

    rng = np.random.default_rng(11)
    z = rng.integers(-50, 3000, (203, 45)).astype(dtype)
    z[5, 6] = -9999  # an undeclared void marker: nodata, reported
    z[150, 3] = 20000  # beyond any elevation on Earth: nodata, reported
    nodata = -32768 if dtype == "int16" else None
    if nodata is not None:
        z[100:103, 10] = nodata
    path = tmp_path / "t.tif"
    with rasterio.open(path, "w", driver="GTiff", width=45, height=203, count=1, dtype=dtype, crs="EPSG:32633",
                       transform=Affine(30, 0, 500000, 0, -30, 4000000), nodata=nodata, tiled=True,
                       blockxsize=16, blockysize=16) as ds:
        ds.write(z, 1)
    with rasterio.open(path) as ds:
        want = ds.read(1).astype(np.float32)
    want[(want == -9999) | (want == 20000) | (want == -32768)] = np.nan

    def read(threads: int):
        monkeypatch.setattr(dem_mod, "READ_THREADS", threads)
        monkeypatch.setattr(dem_mod, "READ_MIN_ROWS", 16)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            values = read_dem_array(path).values
        return values, [str(w.message) for w in caught if issubclass(w.category, OrokitWarning)]

    one, warned_one = read(1)
    many, warned_many = read(3)
    np.testing.assert_array_equal(one, want)
    np.testing.assert_array_equal(many, want)
    assert len(warned_one) == 1 and warned_many == warned_one and " 2 cells hold void markers" in warned_one[0]


@pytest.mark.parametrize("isolation", [True, False])
def test_release_dem_gives_the_same_result_and_frees_the_pixels(tmp_path, isolation):
    from orokit.analysis import analyze

    rng = np.random.default_rng(3)
    z = rng.normal(500.0, 80.0, (48, 61)).astype(np.float32)
    path = _write(tmp_path / "z.tif", z, unit="m")
    kept = analyze(read_dem_array(path), min_prominence_m=5.0, isolation=isolation, geometry=False)
    dem = read_dem_array(path)
    released = analyze(dem, min_prominence_m=5.0, isolation=isolation, geometry=False, release_dem=True)
    assert released.peaks.drop(columns="geometry", errors="ignore").equals(
        kept.peaks.drop(columns="geometry", errors="ignore"))
    assert released.saddles.equals(kept.saddles)
    assert dem.shape == z.shape and dem.values.dtype == np.float32 and np.isnan(dem.values).all()
    assert dem.values.base is not None and dem.values.strides == (0, 0)  # no memory behind it
    assert released.attrs["shape"] == list(z.shape)


def test_release_dem_keeps_the_pixels_when_a_later_step_reads_them(tmp_path):
    from orokit.analysis import analyze

    z = np.random.default_rng(4).normal(500.0, 80.0, (30, 33)).astype(np.float32)
    dem = read_dem_array(_write(tmp_path / "z.tif", z, unit="m"))
    analyze(dem, min_prominence_m=5.0, geometry=False, release_dem=True, depressions=True)
    np.testing.assert_array_equal(dem.values, z)


def test_release_dem_of_integer_pixels():
    """A DemArray of integer pixels (analyze reads them as float64) is released too: it raised
    'cannot convert float NaN to integer' once the engine and the isolation had run."""
    from affine import Affine

    from orokit.analysis import analyze
    from orokit.io.dem import DemArray

    z = np.random.default_rng(5).integers(0, 400, (40, 37)).astype(np.int16)
    kept = analyze(DemArray(z, Affine(30.0, 0, 0, 0, -30.0, 0), None, {"units": "m"}), min_prominence_m=20.0,
                   geometry=False)
    dem = DemArray(z.copy(), Affine(30.0, 0, 0, 0, -30.0, 0), None, {"units": "m"})
    released = analyze(dem, min_prominence_m=20.0, geometry=False, release_dem=True)
    assert len(kept.peaks) > 3 and released.peaks.equals(kept.peaks) and released.saddles.equals(kept.saddles)
    assert dem.shape == z.shape and np.isnan(dem.values).all() and dem.values.strides == (0, 0)


def test_the_mosaic_vrt_of_a_tile_folder_goes_when_the_process_ends(tmp_path):
    """Reading a folder of tiles builds a VRT in TMPDIR/orokit-mosaic-*: it stays while the process may
    read it lazily and was left behind for good (40 such folders in /tmp after one day's test runs)."""
    import os
    import subprocess
    import sys

    tiles, tmp = tmp_path / "tiles", tmp_path / "tmp"
    tiles.mkdir()
    tmp.mkdir()
    z = np.random.default_rng(6).normal(500.0, 50.0, (20, 30)).astype(np.float32)
    _write(tiles / "a.tif", z, unit="m")
    code = ("import glob, os, sys; from orokit.io.dem import read_dem, read_dem_array; "
            "a = read_dem_array(sys.argv[1]); d = read_dem(sys.argv[1], chunks=8); "
            "assert a.shape == (20, 30) and float(d[3:5, 4:6].sum()) == float(a.values[3:5, 4:6].sum()); "
            "print(len(glob.glob(os.path.join(sys.argv[2], 'orokit-mosaic-*'))))")
    out = subprocess.run([sys.executable, "-c", code, str(tiles), str(tmp)], capture_output=True, text=True,
                         check=True, env={**os.environ, "TMPDIR": str(tmp)})
    assert out.stdout.split() == ["2"]  # there while the process runs
    assert list(tmp.iterdir()) == []  # gone after


@pytest.mark.parametrize("chunked", [False, True])
def test_library_reads_leave_gdals_cache_size_alone(tmp_path, monkeypatch, chunked):
    """GDAL's block cache size is global to the process: a library read (in the caller's process) never
    changes it, not even while it reads (before: 32 MB for every thread of the process during a whole
    read and during a chunked ``analyze``); the bound is the ``orokit`` program's own setting
    (tests/cli/test_process_settings.py)."""
    from rasterio.env import get_gdal_config

    import orokit.io.dem as dem
    from orokit.analysis import analyze

    monkeypatch.delenv("GDAL_CACHEMAX", raising=False)
    path = _write(tmp_path / "a.tif", np.arange(600 * 40, dtype=np.float32).reshape(600, 40) % 5000)
    size = get_gdal_config("GDAL_CACHEMAX")  # the cache's size in bytes (rasterio asks GDAL)
    seen: list = []
    opened = dem._open_dataset

    def spy(*args, **kwargs):
        seen.append(get_gdal_config("GDAL_CACHEMAX"))
        return opened(*args, **kwargs)

    monkeypatch.setattr(dem, "_open_dataset", spy)
    if chunked:
        analyze(read_dem(str(path), chunks=200), min_prominence_m=5.0, chunks=200, scheduler="threads")
    else:
        assert read_dem_array(str(path)).values.shape == (600, 40)
    assert len(seen) >= 2 and set(seen) == {size}  # header, then the pixels (stripes or chunks)
    assert get_gdal_config("GDAL_CACHEMAX") == size
