"""Small georeferenced DEMs for tests: ``build_dem`` (also the ``make_dem`` fixture)."""
from __future__ import annotations

from typing import Any

import numpy as np


def build_dem(
    array: Any,
    res: float | tuple[float, float] = 30.0,
    crs: Any = "EPSG:32633",
    nodata: float | None = None,
    origin: tuple[float, float] | None = None,
):
    """Build a DEM DataArray with dims (y, x), transform and CRS.

    ``array`` keeps its dtype (integers stay integers) unless ``nodata`` is given:
    then cells equal to ``nodata`` become NaN in a float copy, as ``read_dem`` does.
    ``res`` is the cell size in CRS units (a number or ``(dx, dy)``); ``origin`` is
    the (west, north) corner, by default (500000, 4000000) for projected CRS,
    (10, 46) degrees for geographic CRS and (0, 0) for ``crs=None`` (local grid).
    Row 0 is the northern row.
    """
    import rioxarray  # noqa: F401
    import xarray as xr
    from pyproj import CRS
    from rasterio.transform import Affine

    from orokit.geodesy import cell_size_key

    a = np.asarray(array)
    if a.ndim != 2:
        raise ValueError(f"make_dem needs a 2-D array, got shape {a.shape}")
    if nodata is not None:
        a = a.astype(np.float64 if a.dtype.kind in "iub" else a.dtype, copy=True)
        a[a == nodata] = np.nan
    dx, dy = (float(res), float(res)) if np.ndim(res) == 0 else (float(res[0]), float(res[1]))
    c = None if crs is None else CRS.from_user_input(crs)
    if origin is None:
        origin = (0.0, 0.0) if c is None else ((10.0, 46.0) if c.is_geographic else (500000.0, 4000000.0))
    west, north = origin
    transform = Affine(dx, 0.0, west, 0.0, -dy, north)
    ny, nx = a.shape
    da = xr.DataArray(
        a,
        dims=("y", "x"),
        coords={"y": north - dy * (np.arange(ny) + 0.5), "x": west + dx * (np.arange(nx) + 0.5)},
        name="elevation",
        attrs={
            "units": "m",
            "source": "make_dem",
            "z_units_in": "m",
            "z_units_assumed": False,
            "local_grid": c is None,
            cell_size_key(c is not None and c.is_geographic): (dx, dy),
            "band": 1,
            "nodata_in": nodata,
        },
    )
    if c is not None:
        da = da.rio.write_crs(c)
    da = da.rio.write_transform(transform)
    return da


