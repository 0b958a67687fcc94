"""A chunk's window: read straight from the file of a ``read_dem`` array, through dask otherwise."""
from __future__ import annotations

import numpy as np
import pytest

from orokit.io.dem import read_dem
from orokit.tiling.engine import _Window


@pytest.fixture()
def dem_tif(make_dem, tmp_path):
    z = np.random.default_rng(5).normal(size=(37, 41)).cumsum(0).astype("float32")
    z[3:6, 7:9] = np.nan
    path = tmp_path / "d.tif"
    make_dem(z).rio.to_raster(path)
    return path


def test_a_read_dem_windows_come_from_its_file_without_dask(dem_tif, monkeypatch):
    """The same values as the dask slice (halo, NaN padding at the raster's edges), and no dask compute:
    computing a slice optimised the whole raster's graph for every chunk (O(chunks) each)."""
    import dask.array

    data = read_dem(str(dem_tif), chunks=8).data
    whole = data.compute()
    boxes = [(0, 8, 0, 8), (8, 16, 8, 16), (32, 37, 40, 41), (0, 37, 0, 41)]
    expected = [_Window(data[:, :] * 1.0, *b).read() for b in boxes]  # another array: through dask
    assert all(_Window(data[:, :] * 1.0, *b).source is None for b in boxes)

    def no_compute(self, *a, **k):
        raise AssertionError("the window went through dask")

    monkeypatch.setattr(dask.array.Array, "compute", no_compute)
    for box, want in zip(boxes, expected):
        w = _Window(data, *box)
        assert w.source is not None
        got = w.read()
        assert got.dtype == np.float32 and got.tobytes() == want.astype(np.float32).tobytes()
    r0, r1, c0, c1 = boxes[1]
    np.testing.assert_array_equal(_Window(data, *boxes[1]).read(), whole[r0 - 1:r1 + 1, c0 - 1:c1 + 1])
