"""Vector maps for the Michel 2015 generator (``--param map=FILE``): peaks, rivers, coast."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from orokit._typing import PathLike
from orokit.errors import InputError
from orokit.generators.michel import VectorMap

__all__ = ["read_vector_map"]


def read_vector_map(path: PathLike) -> VectorMap:
    """Read a vector map (any format geopandas reads: GeoPackage, GeoJSON, shapefile).

    Points are peaks (an ``elevation`` column, if present, gives the map's top elevation),
    (multi)lines are rivers drawn from source to mouth, (multi)polygons are land (the coast);
    every layer of a GeoPackage is read.

    Raises
    ------
    InputError
        Missing or unreadable file, or no point in it.
    """
    import geopandas as gpd
    import pandas as pd
    import shapely

    p = Path(path)
    if not p.is_file():
        raise InputError(f"vector map {p} does not exist; pass a GeoPackage, GeoJSON or shapefile of peaks")
    try:
        layers = [None]
        if p.suffix.lower() == ".gpkg":
            import pyogrio

            layers = [name for name, _ in pyogrio.list_layers(p)]
        frames = [gpd.read_file(p, layer=layer) if layer else gpd.read_file(p) for layer in layers]
    except Exception as exc:  # noqa: BLE001 - any reader failure is a bad input file
        raise InputError(f"cannot read vector map {p}: {exc}") from None
    crs = next((f.crs for f in frames if f.crs is not None), None)
    g = pd.concat([f.to_crs(crs) if (crs is not None and f.crs is not None) else f for f in frames],
                  ignore_index=True)
    g = g[g.geometry.notna() & ~g.geometry.is_empty]
    kind = g.geom_type
    points = g[kind.isin(["Point", "MultiPoint"])].explode(index_parts=False)
    if points.empty:
        raise InputError(f"vector map {p} holds no point: the peaks are its points")
    peaks = np.column_stack([points.geometry.x.to_numpy(), points.geometry.y.to_numpy()])
    top = None
    if "elevation" in points.columns:
        e = pd.to_numeric(points["elevation"], errors="coerce").to_numpy(float)
        if np.isfinite(e).any():
            top = float(np.nanmax(e))
    lines = g[kind.isin(["LineString", "MultiLineString"])].explode(index_parts=False)
    rivers = tuple(np.asarray(geom.coords, float)[:, :2] for geom in lines.geometry)
    polys = g[kind.isin(["Polygon", "MultiPolygon"])]
    land = shapely.union_all(polys.geometry.to_numpy()) if not polys.empty else None
    if land is not None:
        shapely.prepare(land)
    return VectorMap(peaks=peaks, rivers=rivers, land=land, top_m=top, crs=crs.to_wkt() if crs is not None else None)
