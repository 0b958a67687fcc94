"""Small input files (orokit.io.files) and single-band rasters (read_raster_band): errors name the file."""
from __future__ import annotations

import numpy as np
import pytest
import rasterio
from rasterio.transform import Affine

from orokit.errors import InputError
from orokit.io.dem import read_raster_band
from orokit.io.files import read_input_bytes, read_json_file
from orokit.synthesis.terrain_type import load_terrain_type


def test_read_input_bytes_and_json(tmp_path):
    p = tmp_path / "a.json"
    p.write_text('{"k": [1, 2]}')
    assert read_input_bytes(p, what="x") == b'{"k": [1, 2]}'
    assert read_json_file(p, what="x") == {"k": [1, 2]}
    with pytest.raises(InputError, match=r"meta file .*missing\.json does not exist"):
        read_json_file(tmp_path / "missing.json", what="meta file")
    with pytest.raises(InputError, match="is a folder; give the file"):
        read_input_bytes(tmp_path, what="meta file", fix="give the file")
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(InputError, match=r"bad\.json is not valid JSON"):
        read_json_file(tmp_path / "bad.json", what="meta file")


def test_terrain_type_file_errors_name_the_file(tmp_path):
    with pytest.raises(InputError, match=r"terrain type file .*nope\.json does not exist"):
        load_terrain_type(tmp_path / "nope.json")
    with pytest.raises(InputError, match="is a folder; give the JSON file written by `orokit type`"):
        load_terrain_type(tmp_path)


def _write(path, bands: int):
    data = np.arange(bands * 12, dtype=np.float32).reshape(bands, 3, 4)
    data[0, 0, 0] = -9999.0
    with rasterio.open(path, "w", driver="GTiff", width=4, height=3, count=bands, dtype="float32",
                       crs="EPSG:32633", transform=Affine(30, 0, 500000, 0, -30, 4e6), nodata=-9999.0) as f:
        f.write(data)
    return path


def test_read_raster_band(tmp_path):
    da = read_raster_band(_write(tmp_path / "one.tif", 1), what="control raster")
    assert da.dims == ("y", "x") and da.shape == (3, 4) and da.rio.crs.to_epsg() == 32633
    assert np.isnan(da.values[0, 0]) and da.values[2, 3] == 11.0  # nodata masked, values as stored
    with pytest.raises(InputError, match=r"control raster .*two\.tif.* has 2 bands; give a single-band raster"):
        read_raster_band(_write(tmp_path / "two.tif", 2), what="control raster")
    (tmp_path / "junk.tif").write_bytes(b"not a raster")
    with pytest.raises(InputError, match=r"cannot read control raster .*junk\.tif"):
        read_raster_band(tmp_path / "junk.tif", what="control raster")
