"""read_dem on small rasters written by the tests themselves (every supported format)."""
from __future__ import annotations

import math
import warnings
from pathlib import Path

import dask.array as dsa
import numpy as np
import pytest
import rasterio
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from PIL import Image
from rasterio.transform import Affine

from orokit.errors import CRSError, InputError, OrokitWarning, UnitsError
from orokit.io.dem import read_dem

UTM = "EPSG:32633"


def write_tif(path: Path, arr: np.ndarray, *, crs=UTM, transform=None, nodata=None, units=None, **kw) -> Path:
    arr = np.asarray(arr)
    if arr.ndim == 2:
        arr = arr[None]
    transform = transform if transform is not None else Affine(30.0, 0, 500000.0, 0, -30.0, 4000000.0)
    with rasterio.open(
        path, "w", driver="GTiff", width=arr.shape[2], height=arr.shape[1], count=arr.shape[0],
        dtype=arr.dtype, crs=crs, transform=transform, nodata=nodata, **kw,
    ) as dst:
        dst.write(arr)
        if units is not None:
            dst.units = [units] * arr.shape[0]
    return path


def write_png16(path: Path, arr: np.ndarray) -> Path:
    Image.fromarray(np.asarray(arr, dtype=np.uint16)).save(path)
    return path


# --------------------------------------------------------------------------- GeoTIFF
def test_geotiff_projected_int16_nodata(tmp_path):
    raw = np.array([[100, 200, 300], [400, -32768, 600]], dtype=np.int16)
    p = write_tif(tmp_path / "a.tif", raw, nodata=-32768)
    dem = read_dem(p)
    assert dem.dims == ("y", "x") and dem.dtype == np.float32 and dem.shape == (2, 3)
    assert np.isnan(dem.values[1, 1]) and int(dem.isnull().sum()) == 1
    np.testing.assert_array_equal(dem.values[0], [100, 200, 300])
    assert dem.rio.crs.to_epsg() == 32633
    assert tuple(dem.rio.transform())[:6] == (30.0, 0.0, 500000.0, 0.0, -30.0, 4000000.0)
    # cell centres
    np.testing.assert_allclose(dem.x.values, 500000 + 15 + 30 * np.arange(3))
    np.testing.assert_allclose(dem.y.values, 4000000 - 15 - 30 * np.arange(2))
    a = dem.attrs
    assert a["units"] == "m" and a["local_grid"] is False and a["z_units_in"] == "m" and a["z_units_assumed"]
    assert a["cell_size_m"] == (30.0, 30.0) and a["source"] == str(p) and a["nodata_in"] == -32768


def test_geotiff_geographic(tmp_path):
    t = Affine(1 / 1200, 0, -97.5, 0, -1 / 1200, 32.8)
    p = write_tif(tmp_path / "g.tif", np.arange(12, dtype=np.int16).reshape(3, 4) + 150, crs="EPSG:4326", transform=t)
    dem = read_dem(p)
    assert dem.rio.crs.is_geographic and dem.attrs["local_grid"] is False
    assert dem.attrs["cell_size_deg"] == pytest.approx((1 / 1200, 1 / 1200)) and "cell_size_m" not in dem.attrs
    np.testing.assert_allclose(dem.x.values[0], -97.5 + 0.5 / 1200)
    with pytest.raises(CRSError, match="geographic"):
        read_dem(p, cell_size_m=30.0)


def test_float32_sentinel_nodata_compared_in_native_dtype(tmp_path):
    sentinel = np.finfo(np.float32).min  # -3.4028235e38, not exactly a float64 literal
    raw = np.array([[1.5, sentinel], [np.nan, 4.0]], dtype=np.float32)
    p = write_tif(tmp_path / "f.tif", raw, nodata=float(sentinel))
    v = read_dem(p).values
    assert np.isnan(v[0, 1]) and np.isnan(v[1, 0]) and v[0, 0] == 1.5 and v[1, 1] == 4.0


def test_nodata_argument_overrides_file(tmp_path):
    p = write_tif(tmp_path / "n.tif", np.array([[0, 5], [5, 0]], dtype=np.int16))
    assert not read_dem(p).isnull().any()
    assert int(read_dem(p, nodata=0).isnull().sum()) == 2


def test_feet_band_units_and_scale(tmp_path):
    raw = np.array([[1000, 2000], [3000, 29029]], dtype=np.int16)
    p = write_tif(tmp_path / "ft.tif", raw, units="ft")
    dem = read_dem(p)
    assert dem.attrs["z_units_in"] == "ft" and not dem.attrs["z_units_assumed"]
    np.testing.assert_allclose(dem.values, raw.astype(np.float64) * 0.3048, rtol=1e-7)
    with pytest.warns(OrokitWarning, match="declares elevation units"):
        with pytest.warns(OrokitWarning, match="1 cells hold void markers or values beyond"):
            m = read_dem(p, z_units="m")
    # 29029 m is no elevation on Earth: nodata (with the warning), the rest as given
    np.testing.assert_array_equal(m.values, np.where(raw == 29029, np.nan, raw))
    bad = write_tif(tmp_path / "fur.tif", raw, units="furlong")
    with pytest.raises(UnitsError, match="furlong"):
        read_dem(bad)


def test_z_units_feet_given(tmp_path):
    p = write_tif(tmp_path / "x.tif", np.array([[10000]], dtype=np.uint16))
    assert read_dem(p, z_units="feet").values[0, 0] == np.float32(3048.0)
    with pytest.raises(UnitsError, match="accepted"):
        read_dem(p, z_units="yards")


def test_multiband_needs_band(tmp_path):
    raw = np.stack([np.full((2, 2), 1, np.int16), np.full((2, 2), 2, np.int16)])
    p = write_tif(tmp_path / "mb.tif", raw)
    with pytest.raises(InputError, match="2 bands"):
        read_dem(p)
    assert float(read_dem(p, band=2).max()) == 2.0
    with pytest.raises(InputError, match="band=3"):
        read_dem(p, band=3)


def test_crs_conflict_and_assignment(tmp_path):
    p = write_tif(tmp_path / "c.tif", np.ones((2, 2), np.int16))
    with pytest.raises(CRSError, match="conflicts"):
        read_dem(p, crs="EPSG:32632")
    assert read_dem(p, crs="EPSG:32633").rio.crs.to_epsg() == 32633  # same CRS is fine
    q = write_tif(tmp_path / "nocrs.tif", np.ones((2, 2), np.int16), crs=None)
    dem = read_dem(q, crs="EPSG:32633", z_units="m")
    assert dem.rio.crs.to_epsg() == 32633 and dem.attrs["local_grid"] is False
    local = read_dem(q, z_units="m")  # transform but no CRS: local metric grid
    assert local.rio.crs is None and local.attrs["local_grid"] is True
    with pytest.raises(UnitsError, match="no CRS"):
        read_dem(q)


def test_cell_size_conflicts_with_file(tmp_path):
    p = write_tif(tmp_path / "c.tif", np.ones((2, 2), np.int16))
    assert read_dem(p, cell_size_m=30.0).attrs["cell_size_m"] == (30.0, 30.0)
    with pytest.raises(CRSError, match="conflicts"):
        read_dem(p, cell_size_m=25.0)


# --------------------------------------------------------------------------- SRTM .hgt
def test_srtm_hgt_georeference_from_name_and_voids(tmp_path):
    n = 1201
    rng = np.random.default_rng(0)
    z = rng.integers(100, 4000, size=(n, n)).astype(">i2")
    z[10, 20] = -32768
    z[600, 600] = -32768
    p = tmp_path / "N32W098.hgt"
    p.write_bytes(z.tobytes())
    dem = read_dem(p)
    assert dem.shape == (n, n) and dem.rio.crs.to_epsg() == 4326
    t = dem.rio.transform()
    assert t.c == pytest.approx(-98 - 0.5 / 1200) and t.f == pytest.approx(33 + 0.5 / 1200)
    assert t.a == pytest.approx(1 / 1200)
    assert np.isnan(dem.values[10, 20]) and np.isnan(dem.values[600, 600]) and int(dem.isnull().sum()) == 2
    assert dem.values[0, 0] == z[0, 0] and dem.values[-1, -1] == z[-1, -1]


def test_truncated_hgt_is_an_error(tmp_path):
    p = tmp_path / "N32W098.hgt"
    p.write_bytes(np.zeros(1201 * 1000, dtype=">i2").tobytes())
    with pytest.raises(InputError, match="N32W098.hgt"):
        read_dem(p)


# --------------------------------------------------------------------------- ESRI ASCII
ASC = """ncols 4
nrows 3
xllcorner 1000.0
yllcorner 2000.0
cellsize 25.0
NODATA_value -9999
1 2 3 4
5 -9999 7 8
9 10 11 12
"""


def test_esri_ascii_grid(tmp_path):
    p = tmp_path / "g.asc"
    p.write_text(ASC)
    with pytest.raises(UnitsError):  # no CRS, no units declared
        read_dem(p)
    dem = read_dem(p, z_units="m")
    assert dem.shape == (3, 4) and dem.attrs["local_grid"] is True and dem.rio.crs is None
    assert np.isnan(dem.values[1, 1]) and dem.values[2, 3] == 12
    assert tuple(dem.rio.transform())[:6] == (25.0, 0.0, 1000.0, 0.0, -25.0, 2075.0)
    # with a .prj it keeps the CRS and metres are assumed
    (tmp_path / "g.prj").write_text(rasterio.crs.CRS.from_epsg(32633).to_wkt())
    dem2 = read_dem(p)
    assert dem2.rio.crs.to_epsg() == 32633 and dem2.attrs["local_grid"] is False


# --------------------------------------------------------------------------- VRT mosaic
def _vrt(path: Path, sources: list[tuple[str, int]], width: int, height: int) -> Path:
    srcs = "".join(
        f"""<SimpleSource><SourceFilename relativeToVRT="1">{name}</SourceFilename><SourceBand>1</SourceBand>
<SrcRect xOff="0" yOff="0" xSize="{width // 2}" ySize="{height}"/>
<DstRect xOff="{xoff}" yOff="0" xSize="{width // 2}" ySize="{height}"/></SimpleSource>"""
        for name, xoff in sources
    )
    wkt = rasterio.crs.CRS.from_epsg(32633).to_wkt()
    path.write_text(
        f"""<VRTDataset rasterXSize="{width}" rasterYSize="{height}"><SRS>{wkt}</SRS>
<GeoTransform>500000, 30, 0, 4000000, 0, -30</GeoTransform>
<VRTRasterBand dataType="Int16" band="1"><NoDataValue>-32768</NoDataValue>{srcs}</VRTRasterBand></VRTDataset>"""
    )
    return path


def test_vrt_mosaic_of_two_geotiffs(tmp_path):
    left = np.arange(12, dtype=np.int16).reshape(3, 4)
    right = left + 100
    right[0, 0] = -32768
    write_tif(tmp_path / "l.tif", left, nodata=-32768)
    write_tif(tmp_path / "r.tif", right, nodata=-32768, transform=Affine(30, 0, 500120, 0, -30, 4000000))
    vrt = _vrt(tmp_path / "m.vrt", [("l.tif", 0), ("r.tif", 4)], 8, 3)
    dem = read_dem(vrt)
    expected = np.hstack([left, right]).astype(np.float32)
    expected[0, 4] = np.nan
    np.testing.assert_array_equal(dem.values, expected)
    assert dem.rio.crs.to_epsg() == 32633
    np.testing.assert_array_equal(read_dem(vrt, chunks=(2, 3)).values, expected)
    (tmp_path / "r.tif").unlink()
    with pytest.raises(InputError, match="missing source"):
        read_dem(vrt)


def test_a_lazy_dems_name_follows_its_pixels_not_the_spelling_of_its_path(tmp_path, monkeypatch):
    """The dask name (a checkpoint's fingerprint): one file reached by a relative, an absolute or a linked path,
    and a folder of tiles read twice, keep their name (before: a tile folder got a new temporary VRT, hence a new
    name, in every run, so its checkpoint 'belonged to another run' on every rerun; a relative and an absolute
    path too). A touched file, or a touched source of a VRT, gets a new one."""
    import os

    left = np.arange(12, dtype=np.int16).reshape(3, 4)
    tiles = tmp_path / "tiles"
    tiles.mkdir()
    write_tif(tiles / "l.tif", left)
    write_tif(tiles / "r.tif", left + 100, transform=Affine(30, 0, 500120, 0, -30, 4000000))
    vrt = _vrt(tmp_path / "m.vrt", [("tiles/l.tif", 0), ("tiles/r.tif", 4)], 8, 3)
    (tmp_path / "link.tif").symlink_to(tiles / "l.tif")
    monkeypatch.chdir(tmp_path)

    def name(path):
        return read_dem(path, chunks=2).data.name

    assert name("tiles/l.tif") == name(tiles / "l.tif") == name(tmp_path / "link.tif")
    assert name(tiles) == name(tiles) == name("tiles")
    assert name(vrt) == name("m.vrt")
    before = {p: name(p) for p in (tiles, vrt, tiles / "l.tif")}
    st = os.stat(tiles / "r.tif")
    os.utime(tiles / "r.tif", ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    assert name(tiles) != before[tiles] and name(vrt) != before[vrt]
    assert name(tiles / "l.tif") == before[tiles / "l.tif"]


# --------------------------------------------------------------------------- 16-bit PNG
def test_png16_feet_local_grid(tmp_path):
    raw = np.array([[0, 1000, 65535], [29029, 7, 12]], dtype=np.uint16)
    p = write_png16(tmp_path / "d.png", raw)
    with pytest.raises(UnitsError, match="z_units"):
        read_dem(p, cell_size_m=92.61)
    with pytest.raises(CRSError, match="cell_size"):
        read_dem(p, z_units="ft")
    with pytest.warns(OrokitWarning, match=r"1 cells hold void markers .*65535"):
        dem = read_dem(p, z_units="ft", cell_size_m=92.61)
    # exact x 0.3048 from the integer values, no uint16 overflow; 65535 ft (19,975 m) is a void marker
    np.testing.assert_allclose(dem.values, np.where(raw == 65535, np.nan, raw.astype(np.float64) * 0.3048), rtol=1e-7)
    assert np.isnan(dem.values[0, 2]) and dem.values[1, 0] == pytest.approx(29029 * 0.3048)
    assert dem.values[0, 0] == 0.0  # 0 = sea level is data, not nodata
    assert dem.attrs["local_grid"] is True and dem.rio.crs is None and dem.attrs["z_units_in"] == "ft"
    assert tuple(dem.rio.transform())[:6] == (92.61, 0.0, 0.0, 0.0, -92.61, 0.0)
    np.testing.assert_allclose(dem.x.values, [46.305, 138.915, 231.525])
    np.testing.assert_allclose(dem.y.values, [-46.305, -138.915])  # y decreases downward
    with pytest.raises(CRSError, match="geographic"):
        read_dem(p, z_units="ft", cell_size_m=92.61, crs="EPSG:4326")


def test_png16_nonsquare_cell_size(tmp_path):
    p = write_png16(tmp_path / "d.png", np.ones((2, 3)))
    dem = read_dem(p, z_units="m", cell_size_m=(78.0, 92.6))
    assert dem.attrs["cell_size_m"] == (78.0, 92.6)
    for bad in (0, -3, float("nan"), "abc", (1, 2, 3)):
        with pytest.raises(InputError, match="cell_size"):
            read_dem(p, z_units="m", cell_size_m=bad)


# --------------------------------------------------------------------------- chunks
def test_chunked_is_lazy_and_equals_eager(tmp_path):
    rng = np.random.default_rng(1)
    raw = rng.integers(-100, 3000, size=(37, 53)).astype(np.int16)
    raw[rng.random(raw.shape) < 0.1] = -32768
    p = write_tif(tmp_path / "c.tif", raw, nodata=-32768)
    eager = read_dem(p)
    lazy = read_dem(p, chunks={"y": 10, "x": 16})
    assert isinstance(lazy.data, dsa.Array)
    assert lazy.data.chunks == ((10, 10, 10, 7), (16, 16, 16, 5))
    np.testing.assert_array_equal(lazy.values, eager.values)
    assert lazy.rio.transform() == eager.rio.transform()
    for ch in (8, (8, 9), "auto", -1):
        np.testing.assert_array_equal(read_dem(p, chunks=ch).values, eager.values)


def test_chunked_reads_only_windows(tmp_path, monkeypatch):
    from orokit.io import dem as dem_mod

    p = write_tif(tmp_path / "w.tif", np.arange(400, dtype=np.int16).reshape(20, 20))
    calls = []
    orig = dem_mod._BandReader.read

    def spy(self, window=None, out_shape=None):
        calls.append((window, out_shape))
        return orig(self, window, out_shape)

    monkeypatch.setattr(dem_mod._BandReader, "read", spy)
    lazy = read_dem(p, chunks=10)
    assert all(w is None and s is not None for w, s in calls)  # only the small sample so far
    calls.clear()
    block = lazy[:10, :10].values
    assert block[3, 4] == 64 and len(calls) == 1 and calls[0][0].width == 10


def test_chunked_windows_reuse_one_handle_and_see_a_rewritten_file(tmp_path, monkeypatch):
    """Windows of one file open it once per thread (a VRT mosaic's header is parsed at every
    open); a file replaced at the same path (new inode) or rewritten in place is read anew."""
    import os
    import threading

    from orokit.io import dem as dem_mod

    opened = []
    orig = dem_mod._open_dataset

    def spy(path, *, what=""):
        opened.append(path)
        return orig(path, what=what)

    monkeypatch.setattr(dem_mod, "_open_dataset", spy)
    dem_mod._WINDOW_HANDLES.close()
    a = np.arange(900, dtype=np.float32).reshape(30, 30)
    p = write_tif(tmp_path / "h.tif", a)
    lazy = read_dem(p, chunks=7)
    opened.clear()
    np.testing.assert_array_equal(lazy.data.compute(scheduler="sync"), a)
    assert len(opened) == 1  # 25 windows, one open
    # replaced (atomic rename: new inode)
    tmp = write_tif(tmp_path / "h2.tif", a + 1)
    os.replace(tmp, p)
    np.testing.assert_array_equal(read_dem(p, chunks=7).data.compute(scheduler="sync"), a + 1)
    # rewritten in place at a later time
    write_tif(p, a + 2)
    st = os.stat(p)
    os.utime(p, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    np.testing.assert_array_equal(read_dem(p, chunks=7).data.compute(scheduler="sync"), a + 2)
    # threads: each reads with its own handle, same pixels
    out = {}

    def work(k):
        out[k] = read_dem(p, chunks=5).data.compute(scheduler="sync")

    threads = [threading.Thread(target=work, args=(k,)) for k in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for k in range(3):
        np.testing.assert_array_equal(out[k], a + 2)
    dem_mod._WINDOW_HANDLES.close()


# --------------------------------------------------------------------------- errors
def test_missing_empty_corrupt_files(tmp_path):
    with pytest.raises(InputError, match="not found"):
        read_dem(tmp_path / "nope.tif")
    empty = tmp_path / "empty.tif"
    empty.write_bytes(b"")
    with pytest.raises(InputError, match="empty"):
        read_dem(empty)
    junk = tmp_path / "junk.tif"
    junk.write_bytes(b"this is not a raster at all" * 10)
    with pytest.raises(InputError, match="junk.tif"):
        read_dem(junk)
    # a directory is read as a mosaic of its tiles: corrupt tiles are named, empty folders refused
    with pytest.raises(InputError, match="cannot read tile"):
        read_dem(tmp_path)
    (tmp_path / "none").mkdir()
    with pytest.raises(InputError, match="no raster tiles"):
        read_dem(tmp_path / "none")


def test_truncated_geotiff(tmp_path):
    rng = np.random.default_rng(2)
    p = write_tif(tmp_path / "t.tif", rng.integers(0, 3000, size=(256, 256)).astype(np.int16))
    data = p.read_bytes()
    cut = tmp_path / "cut.tif"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match="cut.tif"):
        read_dem(cut)


@pytest.mark.parametrize("chunks", [None, 4])
def test_all_nodata_raster(tmp_path, chunks):
    p = write_tif(tmp_path / "nd.tif", np.full((9, 9), -32768, np.int16), nodata=-32768)
    with pytest.raises(InputError, match="no valid cells"):
        read_dem(p, chunks=chunks)


def test_one_valid_cell_is_found_when_chunked(tmp_path):
    # the decimated sample misses the single valid cell; the streamed check finds it
    raw = np.full((600, 600), -32768, np.int16)
    raw[301, 299] = 5
    p = write_tif(tmp_path / "one.tif", raw, nodata=-32768)
    dem = read_dem(p, chunks=200)
    assert int(dem.notnull().sum()) == 1


def test_bad_chunks(tmp_path):
    p = write_tif(tmp_path / "b.tif", np.ones((4, 4), np.int16))
    with pytest.raises(InputError, match="chunks"):
        read_dem(p, chunks={"band": 2})


# --------------------------------------------------------------------------- property
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    raw=arrays(np.int16, st.tuples(st.integers(1, 12), st.integers(1, 12)), elements=st.integers(-32768, 32767)),
    feet=st.booleans(),
)
def test_property_int16_roundtrip(tmp_path_factory, raw, feet):
    raw[0, 0] = 1  # at least one valid cell
    p = write_tif(tmp_path_factory.mktemp("h") / "p.tif", raw, nodata=-32768, units="ft" if feet else "m")
    expect = raw.astype(np.float64) * (0.3048 if feet else 1.0)
    # void markers and values beyond any elevation on Earth are nodata (and reported)
    void = ((expect < -12_000) | (expect > 9_000) | np.isin(raw, [-9999, -32767])) & (raw != -32768)
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        dem = read_dem(p)
    reported = [w for w in seen if issubclass(w.category, OrokitWarning) and "void markers" in str(w.message)]
    assert len(reported) == int(void.any())
    if void.any():
        assert f"{int(void.sum())} cells" in str(reported[0].message)
    expect[void] = np.nan
    expect[raw == -32768] = np.nan
    np.testing.assert_allclose(dem.values, expect.astype(np.float32), rtol=0, atol=0)
    assert dem.dtype == np.float32 and not math.isnan(float(dem.values[0, 0]))
