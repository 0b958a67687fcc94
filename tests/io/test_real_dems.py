"""Every real DEM of the manifest reads with the right shape, units and a plausible range."""
from __future__ import annotations

import numpy as np
import pytest

from orokit.data import load_manifest, open_dataset_dem

MANIFEST = load_manifest()
DEMS = [d.name for d in MANIFEST.dems()]

# Plausible elevation ranges (metres) from what is known of each area, not from the files.
RANGES = {
    "himalaya-everest": (2000.0, 8848.0 + 15.0),  # Everest 8848.86 m (the crop's max cell is slightly lower)
    "himalaya-annapurna": (500.0, 8091.0 + 15.0),  # Annapurna I 8091 m
    "karakoram": (1500.0, 8611.0 + 15.0),  # K2 8611 m
    "andes-aconcagua": (500.0, 6961.0 + 15.0),  # Aconcagua 6961 m
    "pyrenees": (0.0, 3404.0 + 15.0),  # Aneto 3404 m
    "pysheds-dem": (140.0, 300.0),  # data README: 147-298 m
}


def test_all_thirteen_png_dems_and_the_geotiff_are_listed():
    assert len(DEMS) == 14 and "pysheds-dem" in DEMS


@pytest.mark.realdata
@pytest.mark.parametrize("name", DEMS)
def test_real_dem_reads(real_data, name):
    real_data(name)  # fails in CI / skips locally when the data cannot be obtained
    ds = MANIFEST[name]
    dem = open_dataset_dem(name)
    assert dem.shape == ds.shape and dem.dtype == np.float32 and dem.attrs["units"] == "m"
    assert dem.attrs["z_units_in"] == ds.z_units and dem.attrs["dataset"] == name
    assert dem.attrs["local_grid"] is ds.local_grid
    z = dem.values
    assert np.isfinite(z).mean() > 0.99
    lo, hi = RANGES.get(name, (-50.0, 8900.0))
    assert lo <= np.nanmin(z) and np.nanmax(z) <= hi, (np.nanmin(z), np.nanmax(z))
    if ds.local_grid:
        assert dem.rio.crs is None and dem.attrs["cell_size_m"] == (ds.cell_size_m, ds.cell_size_m)
        assert dem.x.values[-1] == pytest.approx((ds.shape[1] - 0.5) * ds.cell_size_m)
    else:
        assert dem.rio.crs.to_string() == ds.crs


@pytest.mark.realdata
def test_everest_summit_height(real_data):
    real_data("himalaya-everest")
    z = open_dataset_dem("himalaya-everest").values
    assert float(np.nanmax(z)) == pytest.approx(8848.0, abs=15.0)  # feet -> metres done once, right


@pytest.mark.realdata
def test_norway_sea_is_zero_not_nodata(real_data):
    real_data("norway")
    z = open_dataset_dem("norway").values
    assert np.isfinite(z).all() and (z == 0).any()


@pytest.mark.realdata
def test_chunked_real_dem_equals_eager(real_data):
    real_data("pyrenees")
    eager = open_dataset_dem("pyrenees")
    lazy = open_dataset_dem("pyrenees", chunks=512)
    assert lazy.chunks is not None
    np.testing.assert_array_equal(lazy.values, eager.values)
