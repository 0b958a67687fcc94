"""The GeoParquet schema of the analysis tables, made without geopandas, is geopandas's key for key."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from orokit.io.analysis_io import _geoparquet_schema

_LOCAL_TM = ('PROJCS["local TM",GEOGCS["WGS 84",DATUM["WGS_1984",SPHEROID["WGS 84",6378137,298.257223563]],'
             'PRIMEM["Greenwich",0],UNIT["degree",0.0174532925199433]],PROJECTION["Transverse_Mercator"],'
             'PARAMETER["central_meridian",87.3],PARAMETER["scale_factor",1],UNIT["metre",1]]')


@pytest.mark.parametrize("crs", [None, "EPSG:32633", "EPSG:4326", _LOCAL_TM, "EPSG:32645+5773"])
@pytest.mark.parametrize("n", [0, 1])
@pytest.mark.parametrize("attrs", [{}, {"source": "dem.tif"}])
def test_schema_is_geopandas_schema(crs, n, attrs):
    import geopandas as gpd
    from geopandas.io.arrow import _geopandas_to_arrow

    frame = pd.DataFrame({"row": np.arange(n), "x": np.arange(n) + 5e5, "y": np.arange(n) + 4e6,
                          "exact": np.ones(n, bool), "name": ["a"] * n}, index=pd.RangeIndex(n, name="peak_id"))
    frame.attrs.update(attrs)
    want = _geopandas_to_arrow(gpd.GeoDataFrame(frame, geometry=gpd.points_from_xy(frame["x"], frame["y"]),
                                                crs=crs)).schema
    got = _geoparquet_schema(frame, crs)
    assert got.equals(want, check_metadata=True)
    assert got.metadata == want.metadata  # pandas, geo (and PANDAS_ATTRS): the same bytes
    assert got.field("geometry").metadata == want.field("geometry").metadata
