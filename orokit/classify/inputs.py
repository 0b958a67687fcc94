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

import logging
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pandas as pd

from orokit._typing import PathLike, SeedLike
from orokit.classify.features import feature_table, features_from_dem, features_from_region
from orokit.classify.peaklist import read_peaks
from orokit.errors import InputError, OrokitWarning
from orokit.io.analysis_io import read_analysis_meta, read_peak_cells
from orokit.io.region_io import read_region
from orokit.sampling.disks import sample_disks_in_mask
from orokit.sampling.feature_sets import FeatureSet

logger = logging.getLogger(__name__)

RASTER_SUFFIXES = {".tif", ".tiff", ".png", ".hgt", ".asc", ".vrt", ".nc", ".img", ".bil", ".dem", ".zip"}


def default_label(source: PathLike) -> str:
    """Dataset name of an input: ``analysis.json["dataset"]`` of an analysis folder (else
    the folder name), or the file stem."""
    p = Path(source)
    if p.is_dir():
        try:
            dataset = read_analysis_meta(p).get("dataset")
        except (InputError, AttributeError):
            dataset = None
        return str(dataset) if dataset else p.name
    return p.name.split(".")[0]


def _analysis_domain(peaks: pd.DataFrame, meta: dict[str, Any]) -> tuple[np.ndarray, Any, Any] | None:
    """Valid mask, transform and DEM (or None) behind an analysis folder, when known.

    The grid is the one recorded in ``analysis.json`` (``shape``, ``transform``; see
    :func:`orokit.sampling.grid.analysis_grid`); the valid mask comes from the source DEM
    named there when it can be read on that grid (its nodata), else every cell is valid
    and the DEM is None.
    """
    from orokit.sampling.grid import analysis_grid

    try:
        transform, _, shape = analysis_grid(meta, peaks)
    except InputError as exc:
        logger.warning("%s", exc)
        return None
    valid = np.ones(shape, dtype=bool)
    found = None
    src = meta.get("source")
    if src and Path(str(src)).exists():
        try:
            from orokit.io.dem import read_dem

            # a local grid needs its cell size again; a georeferenced file brings its own
            cell = (abs(transform.a), abs(transform.e)) if meta.get("local_grid") else None
            dem = read_dem(str(src), z_units=meta.get("z_units_in") or "m", cell_size_m=cell)
            same = dem.shape == valid.shape and np.allclose(tuple(dem.rio.transform())[:6], tuple(transform)[:6],
                                                            rtol=1e-9, atol=1e-9)
            if same:
                valid = np.isfinite(np.asarray(dem.values, dtype=float))
                found = dem
            else:
                logger.warning("%s no longer matches the analysed grid (shape %s, transform %s); using the full "
                               "extent", src, dem.shape, tuple(transform)[:6])
        except Exception as exc:  # noqa: BLE001 - the extent alone is a usable domain
            logger.warning("cannot read %s for its nodata mask (%s); using the full extent", src, exc)
    return valid, transform, found


def open_input_dem(source: PathLike, *, z_units: str | None = None, cell_size_m: float | None = None) -> Any:
    """The DEM behind an input when it is one: a raster file, or a DEM of the datasets
    manifest given by name (``himalaya-everest``; units and cell size from the manifest).
    ``None`` for analysis folders and peak lists; an error for a name that is neither."""
    p = Path(source)
    if p.exists():
        if p.is_file() and p.suffix.lower() in RASTER_SUFFIXES and not _is_table(p):
            from orokit.io.dem import read_dem

            return read_dem(str(p), z_units=z_units, cell_size_m=cell_size_m)
        return None
    from orokit.data import load_manifest, open_dataset_dem

    names = [d.name for d in load_manifest().dems()]
    if str(source) not in names:
        raise InputError(f"input {source!r} is neither a file nor a DEM of the datasets manifest "
                         f"({', '.join(names)})")
    dem = open_dataset_dem(str(source))
    dem.attrs.setdefault("source", str(source))
    return dem


def has_dem(source: PathLike) -> bool:
    """True when an input brings its DEM: a raster file, a DEM of the datasets manifest, or an
    ``orokit analyze`` folder whose source DEM (``analysis.json``) still exists."""
    p = Path(source)
    if p.is_dir():
        try:
            src = read_analysis_meta(p).get("source")
        except (InputError, AttributeError):
            return False
        return bool(src) and Path(str(src)).is_file()
    if p.exists():
        return p.is_file() and p.suffix.lower() in RASTER_SUFFIXES and not _is_table(p)
    from orokit.data import load_manifest

    return str(source) in {d.name for d in load_manifest().dems()}


def auto_feature_set(sources: Sequence[PathLike]) -> FeatureSet:
    """The feature set ``--features auto`` means: ``terrain`` (orometry plus the DEM's terrain in
    each disk, chosen on the spatial hold-out) when every input has a DEM (:func:`has_dem`),
    else ``orometry`` (peak lists and Divide Trees have no raster)."""
    name = "terrain" if sources and all(has_dem(s) for s in sources) else "orometry"
    logger.info("--features auto: %s", name)
    return FeatureSet.named(name)


def features_for_input(source: PathLike, *, radius_m: float, label: str | None = None,
                       min_prominence_m: float = 30.0, min_peaks: int = 20, max_disks: int = 100,
                       separation: float = 0.5, feature_set: FeatureSet | None = None, relative_elevation: Literal["minmax", "max"] = "minmax",
                       exact_only: bool = False, z_units: str | None = None, cell_size_m: float | None = None,
                       region: Any = None, isolation: PathLike | None = None, crs: Any = None,
                       rng: SeedLike = None) -> pd.DataFrame:
    """Feature table of one input (see the module table for where disks go; a DEM of the
    datasets manifest may be given by name)."""
    p = Path(source)
    label = label or default_label(p)
    kw: dict[str, Any] = dict(radius_m=radius_m, label=label, min_prominence_m=min_prominence_m, min_peaks=min_peaks,
              max_disks=max_disks, separation=separation, feature_set=feature_set, relative_elevation=relative_elevation,
              exact_only=exact_only, rng=rng)
    if region is not None and not hasattr(region, "geometry"):
        region = read_region(region)
    dem = open_input_dem(p, z_units=z_units, cell_size_m=cell_size_m)
    if dem is not None:
        return features_from_dem(dem, **kw)
    peaks = read_peaks(p, crs=crs, z_units=z_units if not p.is_dir() else None, isolation=isolation)
    if region is not None:
        return features_from_region(peaks, region, **kw)
    meta = peaks.attrs.get("analysis")
    if meta is not None:
        raw = read_peak_cells(p) if p.is_dir() else peaks
        dom = _analysis_domain(raw, meta)
        if dom is not None:
            valid, transform, dem = dom
            if feature_set is not None and feature_set.terrain and dem is None:
                raise InputError(f"{p}: feature set {feature_set.name!r} needs the analysed DEM for its terrain "
                                 f"features, but {meta.get('source')!r} (analysis.json 'source') cannot be read on "
                                 f"the analysed grid; give the DEM itself as input, or use --features orometry")
            disks = sample_disks_in_mask(valid, transform=transform, radius_m=radius_m, crs=peaks.crs,
                                         separation=separation, max_disks=max_disks, rng=rng)
            return feature_table(peaks, disks, feature_set=feature_set, min_prominence_m=min_prominence_m, min_peaks=min_peaks,
                                 label=label, source=p.name, crs=peaks.crs, relative_elevation=relative_elevation,
                                 exact_only=exact_only, dem=dem)
    warnings.warn(f"{p}: no region polygon and no DEM extent known; placing disks inside the convex hull of the "
                  f"peaks (pass --region to use a polygon)", OrokitWarning, stacklevel=2)
    import shapely

    hull = shapely.convex_hull(shapely.multipoints(np.column_stack([peaks["x"], peaks["y"]])))
    return features_from_region(peaks, hull, region_crs=peaks.crs, **kw)


def _is_table(p: Path) -> bool:
    return p.suffix.lower() in (".csv", ".txt", ".parquet", ".gpkg")
