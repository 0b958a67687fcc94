"""Region polygons (shapefile, KML, GeoPackage, GeoJSON): where a classification places its disks."""
from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

from orokit._typing import PathLike
from orokit.errors import InputError, OrokitWarning

__all__ = ["read_region"]


def read_region(path: PathLike) -> Any:
    """Read a region polygon file as a GeoDataFrame of its (multi)polygons.

    A file without CRS is taken as lon/lat (EPSG:4326), with a warning.

    Raises
    ------
    InputError
        Missing or unreadable file, or no polygon in it.
    """
    import geopandas as gpd

    p = Path(path)
    if not p.exists():
        raise InputError(f"region file {p} does not exist")
    try:
        g = gpd.read_file(p)
    except Exception as exc:
        raise InputError(f"cannot read region polygon {p}: {exc}") from exc
    g = g[g.geometry.notna() & ~g.geometry.is_empty]
    if g.empty or not g.geom_type.isin(["Polygon", "MultiPolygon"]).any():
        raise InputError(f"region file {p} holds no polygon")
    if g.crs is None:
        warnings.warn(f"region file {p} has no CRS; assuming EPSG:4326 (lon/lat)", OrokitWarning, stacklevel=2)
        g = g.set_crs("EPSG:4326")
    return g
