"""Feature tables from what users have: DEM files, ``orokit analyze`` folders, peak lists.

=================================  ==========================================================
input                              disks are placed
=================================  ==========================================================
DEM (GeoTIFF, PNG, ...)            entirely inside the valid cells (analysis run on the fly)
``orokit analyze`` output folder   inside the analysed DEM's valid cells when the DEM named in
                                   ``analysis.json`` can be read, else inside its extent
peak list + region polygon         inside the polygon eroded by R
peak list alone                    inside the convex hull of the peaks eroded by R (warning)
=================================  ==========================================================
"""
from __future__ import annotations

import json
import logging
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from orokit._typing import PathLike, SeedLike
from orokit.classify.features import feature_table, features_from_dem, features_from_region
from orokit.classify.peaklist import read_peaks
from orokit.errors import InputError, OrokitWarning
from orokit.sampling.disks import sample_disks_in_mask
from orokit.sampling.histograms import HistogramSpec

logger = logging.getLogger(__name__)

RASTER_SUFFIXES = {".tif", ".tiff", ".png", ".hgt", ".asc", ".vrt", ".nc", ".img", ".bil", ".dem", ".zip"}


def default_label(source: PathLike) -> str:
    """Dataset name of an input: file stem, or the folder name of an analysis folder."""
    p = Path(source)
    return p.name if p.is_dir() else p.name.split(".")[0]


def read_region(path: PathLike) -> Any:
    """Read a region polygon file (shapefile, KML, GeoPackage, GeoJSON) as a GeoDataFrame."""
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


def _analysis_domain(folder: Path, meta: dict[str, Any]) -> tuple[np.ndarray, Any, Any] | None:
    """Valid mask, transform and CRS of the DEM behind an analysis folder, when known."""
    attrs = meta.get("attrs", meta)
    src = attrs.get("source") or attrs.get("dem")
    if src and Path(str(src)).exists():
        from orokit.io.dem import read_dem

        dem = read_dem(str(src), z_units=attrs.get("z_units_in"), cell_size=attrs.get("cell_size"))
        return np.isfinite(np.asarray(dem.values, dtype=float)), dem.rio.transform(), dem.rio.crs
    shape = attrs.get("shape")
    tr = attrs.get("transform")
    if shape and tr:
        from affine import Affine

        return np.ones(tuple(shape), dtype=bool), Affine(*tr[:6]), attrs.get("crs")
    return None


def features_for_input(source: PathLike, *, radius_m: float, label: str | None = None,
                       min_prominence_m: float = 30.0, min_peaks: int = 20, max_disks: int = 100,
                       separation: float = 0.5, spec: HistogramSpec | None = None, relative_elevation: str = "minmax",
                       exact_only: bool = False, z_units: str | None = None, cell_size: float | None = None,
                       region: Any = None, isolation: PathLike | None = None, crs: Any = None,
                       rng: SeedLike = None) -> pd.DataFrame:
    """Feature table of one input (see the module table for where disks go)."""
    p = Path(source)
    if not p.exists():
        raise InputError(f"input {p} does not exist")
    label = label or default_label(p)
    kw = dict(radius_m=radius_m, label=label, min_prominence_m=min_prominence_m, min_peaks=min_peaks,
              max_disks=max_disks, separation=separation, spec=spec, relative_elevation=relative_elevation,
              exact_only=exact_only, rng=rng)
    if region is not None and not hasattr(region, "geometry"):
        region = read_region(region)
    if p.is_file() and p.suffix.lower() in RASTER_SUFFIXES and not _is_table(p):
        from orokit.io.dem import read_dem

        dem = read_dem(str(p), z_units=z_units, cell_size=cell_size)
        return features_from_dem(dem, **kw)
    peaks = read_peaks(p, crs=crs, z_units=z_units if not p.is_dir() else None, isolation=isolation)
    if region is not None:
        return features_from_region(peaks, region, **kw)
    meta = peaks.attrs.get("analysis")
    if meta is not None:
        dom = _analysis_domain(p, meta)
        if dom is not None:
            valid, transform, dcrs = dom
            disks = sample_disks_in_mask(valid, transform=transform, radius_m=radius_m,
                                         crs=peaks.crs if peaks.crs is not None else dcrs,
                                         separation=separation, max_disks=max_disks, rng=rng)
            return feature_table(peaks, disks, spec=spec, min_prominence_m=min_prominence_m, min_peaks=min_peaks,
                                 label=label, source=p.name, crs=peaks.crs, relative_elevation=relative_elevation,
                                 exact_only=exact_only)
    warnings.warn(f"{p}: no region polygon and no DEM extent known; placing disks inside the convex hull of the "
                  f"peaks (pass --region to use a polygon)", OrokitWarning, stacklevel=2)
    import shapely

    hull = shapely.convex_hull(shapely.multipoints(np.column_stack([peaks["x"], peaks["y"]])))
    return features_from_region(peaks, hull, region_crs=peaks.crs, **kw)


def _is_table(p: Path) -> bool:
    return p.suffix.lower() in (".csv", ".txt", ".parquet", ".gpkg")
