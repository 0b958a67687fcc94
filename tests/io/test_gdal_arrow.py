"""GeoPackage layers through GDAL's C API (``orokit.io.gdal_arrow``): which GDAL, errors, a full disk."""
from __future__ import annotations

import subprocess
import sys
import textwrap
import threading

import pyarrow as pa
import pytest

from orokit.io import gdal_arrow
from orokit.io.atomic import is_no_space_error

pytestmark = pytest.mark.skipif(gdal_arrow.gdal_library() is None, reason="GDAL's C library not found here")


def test_the_library_is_rasterios_when_pyogrios_gdal_is_loaded_first(tmp_path):
    """rasterio's and pyogrio's wheels each bundle a GDAL (other versions, drivers and settings); with
    pyogrio's mapped first, the writer takes rasterio's (the one orokit reads rasters with, so that
    ``orokit analyze`` loads no second GDAL) and the file reads back through pyogrio's."""
    script = textwrap.dedent(f"""
        import pyogrio
        import rasterio
        from rasterio.env import set_gdal_config
        from orokit.io import gdal_arrow
        from orokit.io.divide_tree_io import read_divide_tree_gpkg, write_divide_tree_gpkg
        from orokit.topology.divide_tree import DivideTree

        lib = gdal_arrow.gdal_library()
        set_gdal_config("OROKIT_TEST_OPTION", "set by rasterio")
        assert lib.CPLGetConfigOption(b"OROKIT_TEST_OPTION", None) == b"set by rasterio", lib._name
        pyogrio.set_gdal_config_options({{"OROKIT_TEST_OPTION2": "set by pyogrio"}})
        assert lib.CPLGetConfigOption(b"OROKIT_TEST_OPTION2", None) is None, lib._name
        tree = DivideTree.from_arrays([[500000, 4e6, 10], [500100, 4e6, 12]], [[500050, 4e6, 5]], [[0, 1, 0]],
                                      crs="EPSG:32633")
        assert read_divide_tree_gpkg(write_divide_tree_gpkg(tree, {str(tmp_path / "t.gpkg")!r})).equals(tree)
    """)
    res = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr[-2000:]


def test_a_failure_in_a_worker_thread_names_the_file_and_prints_nothing(tmp_path, capfd):
    """GDAL's message goes into the OSError (naming the file), not to stderr (GDAL's default
    handler prints ``ERROR 1: ...`` in threads without pyogrio's handler)."""
    path = tmp_path / "missing" / "t.gpkg"
    schema = pa.schema([("a", pa.int64()), ("geometry", pa.binary())])
    errors: list[BaseException] = []

    def write() -> None:
        try:
            gdal_arrow.write_arrow_layer(path, "t", schema, [], geometry_name="geometry", geometry_type="Point",
                                         crs=None, layer_options={})
        except OSError as exc:
            errors.append(exc)

    thread = threading.Thread(target=write)
    thread.start()
    thread.join()
    assert len(errors) == 1 and str(path) in str(errors[0]) and "cannot open or create" in str(errors[0])
    assert "ERROR" not in capfd.readouterr().err


@pytest.mark.parametrize("message", [
    # the writers' errors when the disk filled during a GeoPackage (measured on a full tmpfs)
    "/out/.t.gpkg.tmp-0123456789ab.gpkg: cannot commit the layer: sqlite3_exec(COMMIT) failed: database or disk is full",
    "Error while writing batch to OGR layer: sqlite3_exec(COMMIT) failed: database or disk is full",
])
def test_a_full_disk_in_a_geopackage_is_a_full_disk(message):
    assert is_no_space_error(OSError(message))
    try:
        raise RuntimeError("writing dividetree.gpkg failed") from OSError(message)
    except RuntimeError as exc:
        assert is_no_space_error(exc)
