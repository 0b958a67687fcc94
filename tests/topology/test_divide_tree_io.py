"""Divide Tree files: reference TXT format and GeoPackage layers."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from orokit.errors import DivideTreeError, InputError
from orokit.io.divide_tree_io import (
    read_divide_tree_gpkg,
    read_divide_tree_txt,
    write_divide_tree_gpkg,
    write_divide_tree_txt,
)
from orokit.topology.divide_tree import DivideTree

SMALL_TXT = """Peaks 3
1 0.002500 0.005000 1000 3 6
2 0.005000 0.000000 900 6 0
3 0.000000 0.007500 1200 0 9
PromSaddles 2
1 0.003333 0.003333 800 4 4
2 0.000833 0.006667 950 1 8
BasinSaddles 0
Runoffs 2
1 0.000000 0.000000 500 0 0
2 0.005833 0.000000 880 7 0
Edges 2
1 2 1
1 3 2
RunoffEdges 2
2 0
2 1
"""


@pytest.fixture
def small_txt(tmp_path):
    p = tmp_path / "small.txt"
    p.write_text(SMALL_TXT)
    return p


def test_read_small_txt(small_txt):
    tree = read_divide_tree_txt(small_txt, height=10)
    assert tree.n_peaks == 3 and tree.n_saddles == 2
    p = tree.peaks
    # x = column from the west, y = row from the south: row = H - 1 - y
    assert p["row"].tolist() == [3, 9, 0] and p["col"].tolist() == [3, 6, 0]
    cell = 3 * 30.87  # a = x * 3 / 3600 -> 3 arc-seconds
    assert tree.attrs["cell_size_m"] == pytest.approx(cell)
    assert p["x"].tolist() == pytest.approx([(3 + 0.5) * cell, (6 + 0.5) * cell, 0.5 * cell])
    assert p["y"].tolist() == pytest.approx([-(3 + 0.5) * cell, -(9 + 0.5) * cell, -0.5 * cell])
    assert p["elevation"].tolist() == pytest.approx([304.8, 274.32, 365.76])
    assert tree.edges.to_numpy().tolist() == [[0, 1, 0], [0, 2, 1]]
    runoffs = tree.attrs["runoffs"]
    assert len(runoffs) == 2 and runoffs["peak_txt_id"].tolist() == [2, 2]
    table = tree.prominence_table()
    assert table["prominence"].tolist() == pytest.approx([50 * 0.3048, 100 * 0.3048, 1200 * 0.3048])


def test_cell_size_and_units_override(small_txt):
    tree = read_divide_tree_txt(small_txt, cell_size_m=10.0, z_units="m", height=10)
    assert tree.peaks["x"].iloc[0] == pytest.approx(35.0)
    assert tree.peaks["elevation"].iloc[0] == 1000.0
    no_h = read_divide_tree_txt(small_txt, cell_size_m=10.0)
    assert "row" not in no_h.peaks.columns
    assert no_h.peaks["y"].iloc[0] == pytest.approx(65.0)  # measured from the south edge


def test_txt_round_trip_is_byte_identical(small_txt, tmp_path):
    tree = read_divide_tree_txt(small_txt, height=10)
    out = write_divide_tree_txt(tree, tmp_path / "out.txt")
    assert out.read_text() == SMALL_TXT


def test_txt_round_trip_after_prune(small_txt, tmp_path):
    full = read_divide_tree_txt(small_txt, height=10)
    tree = full.prune(60 * 0.3048)  # drops txt peak 1 (50 ft)
    assert tree.n_peaks == 2
    write_divide_tree_txt(tree, tmp_path / "p.txt")
    back = read_divide_tree_txt(tmp_path / "p.txt", height=10)
    assert back.equals(tree)
    assert back.attrs["runoffs"]["peak_txt_id"].tolist() == [1, 1]  # txt peak 2 is now id 1
    tree = full.prune(150 * 0.3048)  # only the root is left
    write_divide_tree_txt(tree, tmp_path / "q.txt")
    back = read_divide_tree_txt(tmp_path / "q.txt", height=10)
    assert back.n_peaks == 1 and len(back.edges) == 0
    assert len(back.attrs["runoffs"]) == 0  # the runoffs belonged to a pruned peak


def test_write_tree_without_raw_columns(tmp_path):
    tree = DivideTree(
        pd.DataFrame({"x": [15.0, 45.0], "y": [-5.0, -25.0], "elevation": [100.0, 90.0], "row": [0, 2], "col": [1, 4]}),
        pd.DataFrame({"x": [25.0], "y": [-15.0], "elevation": [80.0], "row": [1], "col": [2]}),
        pd.DataFrame({"peak_a": [0], "peak_b": [1], "saddle": [0]}),
    )
    with pytest.raises(InputError, match="height"):
        write_divide_tree_txt(tree, tmp_path / "t.txt")
    write_divide_tree_txt(tree, tmp_path / "t.txt", height=3, cell_size_m=10.0, z_units="m")
    back = read_divide_tree_txt(tmp_path / "t.txt", height=3, cell_size_m=10.0, z_units="m")
    assert back.peaks[["row", "col"]].to_numpy().tolist() == [[0, 1], [2, 4]]
    assert back.peaks[["x", "y", "elevation"]].to_numpy() == pytest.approx(tree.peaks[["x", "y", "elevation"]].to_numpy())


def test_gpkg_round_trip(small_txt, tmp_path):
    tree = read_divide_tree_txt(small_txt, height=10)
    path = write_divide_tree_gpkg(tree, tmp_path / "tree.gpkg")
    back = read_divide_tree_gpkg(path)
    assert back.equals(tree)
    assert back.attrs["height"] == 10 and back.attrs["cell_size_m"] == pytest.approx(tree.attrs["cell_size_m"])
    assert len(back.attrs["runoffs"]) == 2
    import pyogrio

    layers = dict(pyogrio.list_layers(path))
    assert layers["peaks"] == "Point" and layers["ridges"] == "LineString"
    assert not list(tmp_path.glob(".*tmp*"))  # no temporary file left behind
    # the GeoPackage is written without SQLite's per-transaction syncs (atomic_path syncs the file once):
    # the process-wide setting of the GDAL the writers use is restored after the write
    assert _writers_option("OGR_SQLITE_SYNCHRONOUS") is None
    _set_writers_option("OGR_SQLITE_SYNCHRONOUS", "NORMAL")
    try:
        write_divide_tree_gpkg(tree, tmp_path / "again.gpkg")
        assert _writers_option("OGR_SQLITE_SYNCHRONOUS") == "NORMAL"
    finally:
        _set_writers_option("OGR_SQLITE_SYNCHRONOUS", None)
    assert read_divide_tree_gpkg(tmp_path / "again.gpkg").equals(tree)


@pytest.mark.parametrize("parallel", [False, True])
def test_sqlite_sync_is_off_in_the_writing_threads_only(small_txt, tmp_path, monkeypatch, parallel):
    """While the GeoPackage is written, its writing threads run SQLite without per-transaction
    syncs, but the process's GDAL setting is untouched: a caller's thread writing meanwhile keeps
    its own (before session 13 it was set process-wide for the whole write)."""
    import threading

    import orokit.io.wkb as wkb

    seen: list[tuple[object, object]] = []
    point_wkb = wkb.point_wkb

    def spy(x, y):  # called in each writing thread, inside the write
        other: list[object] = []
        probe = threading.Thread(target=lambda: other.append(_writers_option("OGR_SQLITE_SYNCHRONOUS")))
        probe.start()
        probe.join()
        seen.append((_writers_option("OGR_SQLITE_SYNCHRONOUS"), other[0]))
        return point_wkb(x, y)

    monkeypatch.setattr(wkb, "point_wkb", spy)
    tree = read_divide_tree_txt(small_txt, height=10)
    path = write_divide_tree_gpkg(tree, tmp_path / "tree.gpkg", parallel=parallel)
    assert read_divide_tree_gpkg(path).equals(tree)
    assert len(seen) >= 3  # peaks, saddles, runoffs
    assert all(mine == "OFF" for mine, _ in seen)
    assert all(theirs is None for _, theirs in seen)
    assert _writers_option("OGR_SQLITE_SYNCHRONOUS") is None  # restored in this thread


def _writers_option(name: str) -> str | None:
    """A GDAL configuration option as the GeoPackage writers' GDAL (``gdal_arrow.gdal_library()``) sees it
    in the calling thread."""
    from orokit.io import gdal_arrow

    value = gdal_arrow.gdal_library().CPLGetConfigOption(name.encode(), None)
    return None if value is None else value.decode()


def _set_writers_option(name: str, value: str | None) -> None:
    """Set (None: unset) a process-wide GDAL configuration option of the writers' GDAL."""
    import ctypes

    from orokit.io import gdal_arrow

    lib = gdal_arrow.gdal_library()
    lib.CPLSetConfigOption.argtypes = [ctypes.c_char_p, ctypes.c_char_p]
    lib.CPLSetConfigOption(name.encode(), None if value is None else value.encode())


_LOCAL_TM = ('PROJCS["local TM",GEOGCS["WGS 84",DATUM["WGS_1984",SPHEROID["WGS 84",6378137,298.257223563]],'
             'PRIMEM["Greenwich",0],UNIT["degree",0.0174532925199433]],PROJECTION["Transverse_Mercator"],'
             'PARAMETER["latitude_of_origin",0],PARAMETER["central_meridian",87.3],PARAMETER["scale_factor",1],'
             'PARAMETER["false_easting",0],PARAMETER["false_northing",0],UNIT["metre",1]]')


@pytest.mark.parametrize("crs", [None, "EPSG:32633", "EPSG:4326", _LOCAL_TM])
def test_gpkg_writers_write_the_same_layers(small_txt, tmp_path, monkeypatch, crs):
    """GDAL's C API without the GIL (``orokit.io.gdal_arrow``) and ``parallel=True`` (saddles and ridges
    from a second GeoPackage, copied by SQLite) write the layers pyogrio's writer writes, in the same order;
    GDAL reads and appends to the file; no temporary file is left."""
    import contextlib
    import dataclasses

    import geopandas as gpd
    import pyogrio
    from shapely.geometry import Point

    from orokit.io import gdal_arrow

    from rasterio.env import set_gdal_config

    lib = gdal_arrow.gdal_library()
    assert lib is not None  # found on this platform: the test compares both writers
    set_gdal_config("OROKIT_TEST_WHICH_GDAL", "rasterio's")  # the writers use rasterio's GDAL, not pyogrio's
    assert lib.CPLGetConfigOption(b"OROKIT_TEST_WHICH_GDAL", None) == b"rasterio's", lib._name
    tree = dataclasses.replace(read_divide_tree_txt(small_txt, height=10), crs=crs)
    extra = {"depressions": gpd.GeoDataFrame({"depth": [3.0, 4.5]}, geometry=[Point(0, 0), Point(1, 1)], crs=crs)}
    with monkeypatch.context() as m, contextlib.ExitStack() as stack:
        m.setattr(gdal_arrow, "gdal_library", lambda: None)  # pyogrio's writer
        if crs is None:  # it says so (orokit swaps no warning filters: tested below)
            stack.enter_context(pytest.warns(UserWarning, match="'crs' was not provided"))
        one = write_divide_tree_gpkg(tree, tmp_path / "one.gpkg", layers=extra)
    two = write_divide_tree_gpkg(tree, tmp_path / "two.gpkg", layers=extra, parallel=True)
    layers = pyogrio.list_layers(one).tolist()
    assert pyogrio.list_layers(two).tolist() == layers
    assert [name for name, _ in layers] == ["peaks", "saddles", "ridges", "runoffs", "basin_saddles", "depressions",
                                            "orokit_metadata"]
    for name, _ in layers:
        a, b = pyogrio.read_dataframe(one, layer=name), pyogrio.read_dataframe(two, layer=name)
        assert a.equals(b), name
        info_a, info_b = pyogrio.read_info(one, layer=name), pyogrio.read_info(two, layer=name)
        assert info_a["features"] == info_b["features"] == len(a), name
        assert info_a["crs"] == info_b["crs"], name
        if info_a["geometry_type"]:
            assert np.array_equal(info_a["total_bounds"], info_b["total_bounds"]), name
    back = read_divide_tree_gpkg(two)
    assert back.equals(tree) and back.equals(read_divide_tree_gpkg(one))
    assert not list(tmp_path.glob(".*tmp*"))
    # the file stays a GeoPackage GDAL edits: a layer appended and the copied layers' feature counts kept
    pyogrio.write_dataframe(pd.DataFrame({"a": [1, 2]}), two, layer="more")
    assert pyogrio.read_info(two, layer="saddles", force_feature_count=True)["features"] == tree.n_saddles


def test_gpkg_writer_thread_leaves_the_warning_filters_alone(small_txt, tmp_path, monkeypatch):
    """``write_divide_tree_gpkg`` runs in a writer thread beside others (``write_analysis``): it must not
    swap the process's warning filters (``warnings.catch_warnings`` is not thread-safe: another thread's
    filters or recorder were lost or kept for good). Before: every layer was written inside one, to hide
    pyogrio's warning about a tree without CRS; GDAL's C API writes such a tree without it."""
    import dataclasses
    import threading
    import warnings

    import geopandas as gpd
    from shapely.geometry import Point

    from orokit.io import gdal_arrow

    tree = dataclasses.replace(read_divide_tree_txt(small_txt, height=10), crs=None)
    extra = {"depressions": gpd.GeoDataFrame({"depth": [3.0]}, geometry=[Point(0, 0)], crs=None)}
    filters = warnings.filters
    swapped: list[str] = []
    write = gdal_arrow.write_arrow_layer

    def spy(path, layer, *args, **kwargs):
        if warnings.filters is not filters:
            swapped.append(layer)
        return write(path, layer, *args, **kwargs)

    monkeypatch.setattr(gdal_arrow, "write_arrow_layer", spy)
    errors: list[BaseException] = []

    def run() -> None:
        try:
            write_divide_tree_gpkg(tree, tmp_path / "t.gpkg", layers=extra, parallel=True)
        except BaseException as exc:  # noqa: BLE001 - raised below, in the test's thread
            errors.append(exc)

    thread = threading.Thread(target=run)
    thread.start()
    thread.join()
    assert not errors, errors
    assert swapped == [] and warnings.filters is filters
    assert read_divide_tree_gpkg(tmp_path / "t.gpkg").equals(tree)


def test_gpkg_keeps_crs(tmp_path):
    from pyproj import CRS

    tree = DivideTree.from_arrays([[500000, 4e6, 10], [500100, 4e6, 12]], [[500050, 4e6, 5]], [[0, 1, 0]],
                                  crs=CRS.from_epsg(32633), attrs={"min_prominence_m": 30.0})
    back = read_divide_tree_gpkg(write_divide_tree_gpkg(tree, tmp_path / "t.gpkg"))
    assert back.crs.to_epsg() == 32633
    assert back.attrs["min_prominence_m"] == 30.0
    assert back.equals(tree)
    text = DivideTree.from_arrays([[500000, 4e6, 10], [500100, 4e6, 12]], [[500050, 4e6, 5]], [[0, 1, 0]],
                                  crs="EPSG:32633")  # a CRS given as text (synthesized trees carry one)
    assert read_divide_tree_gpkg(write_divide_tree_gpkg(text, tmp_path / "s.gpkg")).crs.to_epsg() == 32633


def test_gpkg_of_older_versions_reads_the_old_attr_keys(tmp_path):
    """Files written before the naming rules (``min_prominence``, ``cell_size``) read under the new keys."""
    tree = DivideTree.from_arrays([[0, 0, 10], [100, 0, 12]], [[50, 0, 5]], [[0, 1, 0]],
                                  attrs={"min_prominence": 30.0, "cell_size": 92.61})
    back = read_divide_tree_gpkg(write_divide_tree_gpkg(tree, tmp_path / "old.gpkg"))
    assert back.attrs["min_prominence_m"] == 30.0 and back.attrs["cell_size_m"] == 92.61
    assert "min_prominence" not in back.attrs and "cell_size" not in back.attrs


def test_gpkg_missing_layers(tmp_path):
    import geopandas as gpd
    from shapely.geometry import Point

    p = tmp_path / "other.gpkg"
    gpd.GeoDataFrame({"a": [1]}, geometry=[Point(0, 0)], crs=4326).to_file(p, layer="foo")
    with pytest.raises(InputError, match="lacks the layers"):
        read_divide_tree_gpkg(p)
    with pytest.raises(InputError, match="does not exist"):
        read_divide_tree_gpkg(tmp_path / "missing.gpkg")


@pytest.mark.parametrize(
    "text, match",
    [
        ("Peaks 999999999999\n1 0 0 10 0 0\n", r"small.txt:2: file ends inside section Peaks"),
        ("Peaks -3\n", "non-negative"),
        ("Peaks x\n", "non-negative"),
        ("Hello 2\n", "section header"),
        ("Peaks 1\n1 0 0 10 0\n", "6 fields"),
        ("Peaks 1\n1 0 0 ten 0 0\n", "non-numeric"),
        ("Peaks 1\n1 0 0 nan 0 0\n", "non-finite"),
        ("Peaks 1\n1 0.1 0 10 1.5 0\nPromSaddles 0\nEdges 0\n", "integers"),
        ("Peaks 1\n1 0.1 0 10 1 0\nPromSaddles 0\nEdges 1\n1 2 1\n", "peak id 2"),
        ("Peaks 2\n1 0.1 0 10 1 0\n1 0.1 0 10 2 0\nPromSaddles 0\nEdges 0\n", "repeats id 1"),
        ("Peaks 1\n1 0.1 0 10 1 0\nPromSaddles 0\n", "missing section 'Edges'"),
        ("Peaks 1\n1 0.1 0 10 1 0\nPeaks 0\n", "appears twice"),
    ],
)
def test_corrupt_txt_names_the_problem(tmp_path, text, match):
    p = tmp_path / "small.txt"
    p.write_text(text)
    with pytest.raises(InputError, match=match):
        read_divide_tree_txt(p)


def test_every_truncation_is_a_clean_error_or_a_valid_tree(tmp_path):
    p = tmp_path / "cut.txt"
    data = SMALL_TXT.encode()
    for n in range(len(data)):
        p.write_bytes(data[:n])
        try:
            tree = read_divide_tree_txt(p, height=10)
        except InputError as exc:
            assert str(p) in str(exc)
        else:  # a cut inside a number of the last line can still parse
            tree.validate(check_elevations=False)


def test_binary_garbage_is_an_input_error(tmp_path):
    p = tmp_path / "bin.txt"
    p.write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00\xff\xfe")
    with pytest.raises(InputError):
        read_divide_tree_txt(p)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(pos=st.integers(0, len(SMALL_TXT) - 1), junk=st.text(max_size=6))
def test_mutated_files_never_crash(tmp_path, pos, junk):
    p = tmp_path / "mut.txt"
    p.write_text(SMALL_TXT[:pos] + junk + SMALL_TXT[pos + 1:])
    try:
        tree = read_divide_tree_txt(p)
    except (InputError, DivideTreeError):
        pass  # the reader's documented errors
    else:
        tree.validate()  # whatever it accepts is a valid tree


@pytest.mark.realdata
@pytest.mark.parametrize("name", ["alaska", "pyrenees"])
def test_reference_files_round_trip(real_data, tmp_path, name):
    from PIL import Image

    src = real_data(f"dems/{name}.txt")
    h = np.asarray(Image.open(real_data(f"dems/{name}.png"))).shape[0]
    tree = read_divide_tree_txt(src, height=h)
    assert tree.n_peaks == len(tree.edges) + 1  # a connected (not finalised) tree
    write_divide_tree_txt(tree, tmp_path / "rt.txt")
    assert (tmp_path / "rt.txt").read_bytes() == src.read_bytes()
    back = read_divide_tree_gpkg(write_divide_tree_gpkg(tree, tmp_path / "rt.gpkg"))
    assert back.equals(tree)
    np.testing.assert_allclose(back.prominence(), tree.prominence())


@pytest.mark.parametrize("pos", [33, 35])
def test_huge_pixel_coordinates_are_an_input_error(tmp_path, pos):
    """Found by the fuzz test: 1E100 in an integer field is refused, not cast with a warning."""
    p = tmp_path / "huge.txt"
    p.write_text(SMALL_TXT[:pos] + "1E100" + SMALL_TXT[pos + 1:])
    with pytest.raises((InputError, DivideTreeError)):
        read_divide_tree_txt(p)
