"""Feature tables: one row per disk with its orometric features (histograms, summaries).

Pipeline per region (Argudo et al. 2019, section 4.2):

1. disks of radius R placed by blue noise (:mod:`orokit.sampling.disks`) inside the
   DEM's valid area or inside the region polygon eroded by R;
2. the peaks with prominence >= eps (30 m) within distance R of the centre (geodesic
   for geographic CRS);
3. disks with fewer than ``min_peaks`` peaks (20) are skipped and counted (one
   :class:`~orokit.errors.OrokitWarning` per call);
4. per-peak metrics relative to the disk (:mod:`orokit.metrics.disk`), turned into the
   feature vector of the chosen :class:`~orokit.sampling.feature_sets.FeatureSet` at each
   of its radius fractions (:func:`~orokit.sampling.feature_sets.disk_feature_vector`).

Peaks whose prominence is flagged not exact (key saddle may lie outside the data) are
kept by default, as in the paper's experiments on cropped DEMs; ``exact_only=True``
drops them.
"""
from __future__ import annotations

import dataclasses
import logging
import warnings
from collections.abc import Sequence
from typing import Any

import geopandas as gpd
import numpy as np
import pandas as pd
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from orokit import __version__
from orokit._typing import PathLike, SeedLike
from orokit.classify.peaklist import NORMALIZED_COLUMNS, is_geographic, peak_geometry
from orokit.errors import InputError, OrokitWarning, SchemaError
from orokit.metrics.disk import RELATIVE_ELEVATION_DEFAULT, RelativeElevation
from orokit.sampling.disks import sample_disks_in_mask, sample_disks_in_polygon
from orokit.sampling.feature_sets import FeatureSet, disk_feature_vector
from orokit.sampling.histograms import HistogramSpec

logger = logging.getLogger(__name__)

#: non-histogram columns of a feature table, in order
META_COLUMNS = ["label", "source", "disk_id", "x", "y", "lon", "lat", "radius_m", "n_peaks"]
_EARTH_R = 6_371_008.8


def _unit_vectors(lon: NDArray, lat: NDArray) -> NDArray[np.float64]:
    lo, la = np.radians(lon), np.radians(lat)
    return np.column_stack([np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)])


def peaks_in_disks(peaks: pd.DataFrame, centres: NDArray[np.float64], radius_m: float, *,
                   geographic: bool) -> list[NDArray[np.int64]]:
    """Positional indices of the peaks within ``radius_m`` of each centre.

    Geographic: candidates from a 3-D unit-sphere k-d tree (handles the antimeridian
    and poles), then exact WGS84 geodesic distances. Otherwise Euclidean.
    """
    x = peaks["x"].to_numpy(dtype=float)
    y = peaks["y"].to_numpy(dtype=float)
    if len(x) == 0:
        return [np.zeros(0, dtype=np.int64) for _ in range(len(centres))]
    if not geographic:
        tree = cKDTree(np.column_stack([x, y]))
        return [np.sort(np.asarray(i, dtype=np.int64)) for i in tree.query_ball_point(centres, radius_m)]
    from orokit.geodesy import WGS84 as geod

    tree = cKDTree(_unit_vectors(x, y))
    chord = 2 * np.sin(min(radius_m * 1.01 / (_EARTH_R * 0.995), np.pi) / 2)
    out = []
    for (cx, cy), cand in zip(centres, tree.query_ball_point(_unit_vectors(centres[:, 0], centres[:, 1]), chord)):
        cand = np.asarray(cand, dtype=np.int64)
        if len(cand):
            _, _, d = geod.inv(np.full(len(cand), cx), np.full(len(cand), cy), x[cand], y[cand])
            cand = cand[np.asarray(d) <= radius_m]
        out.append(np.sort(cand))
    return out


def nearest_peak_distance(peaks: pd.DataFrame, *, geographic: bool) -> NDArray[np.float64]:
    """Distance (m) from each peak to the nearest other peak of ``peaks`` (NaN when alone).

    Geographic: the nearest peak on the unit sphere, then its WGS84 geodesic distance.
    Otherwise Euclidean. Peaks at the same place give 0.
    """
    x = peaks["x"].to_numpy(dtype=float)
    y = peaks["y"].to_numpy(dtype=float)
    if len(x) < 2:
        return np.full(len(x), np.nan)
    if not geographic:
        _, j = cKDTree(np.column_stack([x, y])).query(np.column_stack([x, y]), k=2)
        return np.hypot(x[j[:, 1]] - x, y[j[:, 1]] - y)
    from orokit.geodesy import WGS84 as geod

    u = _unit_vectors(x, y)
    _, j = cKDTree(u).query(u, k=2)
    _, _, d = geod.inv(x, y, x[j[:, 1]], y[j[:, 1]])
    return np.asarray(d, dtype=float)


def feature_table(peaks: pd.DataFrame, disks: pd.DataFrame, *, feature_set: FeatureSet | None = None,
                  min_prominence_m: float = 30.0, min_peaks: int = 20, label: str | None = None,
                  source: str | None = None, crs: Any = None,
                  relative_elevation: RelativeElevation = RELATIVE_ELEVATION_DEFAULT,
                  exact_only: bool = False, dem: Any = None) -> pd.DataFrame:
    """Features of the peaks of each disk.

    Parameters
    ----------
    peaks : DataFrame
        Normalized peak table (:func:`orokit.classify.peaklist.peak_geometry`) or an
        orokit peaks table (normalized on the fly).
    disks : DataFrame
        Disk centres (columns x, y, radius_m, optional disk_id) in the peaks' CRS, as
        returned by :mod:`orokit.sampling.disks`.
    feature_set : FeatureSet, optional
        What each disk's vector holds (default :meth:`FeatureSet.orometry`;
        :meth:`FeatureSet.paper` is the paper's Table 1).
    min_prominence_m : float
        eps: only peaks with prominence >= eps count (paper: 30 m).
    min_peaks : int
        Disks with fewer counted peaks within R are skipped (paper: 20).
    label, source : str, optional
        Region label and input name stored in each row.
    crs : CRS-like, optional
        CRS of peaks and disks (default ``peaks.crs``); geographic means geodesic distances.
    relative_elevation : {"minmax", "max"}
        See :mod:`orokit.metrics.disk`.
    exact_only : bool
        Drop peaks whose prominence is flagged not exact.
    dem : xarray.DataArray, optional
        The DEM the peaks come from (same CRS): needed by a feature set with ``terrain``
        (:mod:`orokit.classify.terrain`).

    Returns
    -------
    DataFrame
        One row per kept disk: :data:`META_COLUMNS` then ``feature_set.columns``.
        ``attrs`` hold the parameters, ``n_disks_skipped`` and the feature set.
    """
    fs = feature_set or FeatureSet.orometry()
    crs = crs if crs is not None else getattr(peaks, "crs", None)
    if not set(NORMALIZED_COLUMNS) <= set(peaks.columns):
        peaks = peak_geometry(peaks, crs=crs)
    if len(disks) and not {"x", "y", "radius_m"} <= set(disks.columns):
        raise SchemaError(f"disks need columns x, y, radius_m; got {list(disks.columns)}")
    if min_peaks < 1:
        raise InputError(f"min_peaks must be >= 1, got {min_peaks}")
    if fs.terrain and dem is None:
        raise InputError(f"feature set {fs.name!r} has terrain (raster) features and needs the DEM; peak lists and "
                         f"Divide Trees have none: give the DEM (or its analysis folder) as input, or use "
                         f"--features orometry")
    terrain = None
    if fs.terrain:
        from orokit.classify.terrain import terrain_fields

        terrain = terrain_fields(dem, cell_size_m=fs.terrain_cell_size_m)
    geo = is_geographic(crs)
    keep = peaks["prominence"].to_numpy(dtype=float) >= min_prominence_m
    if exact_only:
        keep &= peaks["prominence_exact"].to_numpy(dtype=bool)
    counted = peaks.loc[keep]
    arrays = [counted[c].to_numpy(dtype=float) for c in _METRIC_INPUTS]
    spacing = nearest_peak_distance(counted, geographic=geo) if fs.pattern else None
    radii = disks["radius_m"].to_numpy(dtype=float) if len(disks) else np.zeros(0)
    rows: list[dict[str, Any]] = []
    vectors: list[NDArray[np.float64]] = []
    n_skipped = 0
    centres = disks[["x", "y"]].to_numpy(dtype=float) if len(disks) else np.zeros((0, 2))
    for r in np.unique(radii):
        sel = np.flatnonzero(radii == r)
        members = {f: peaks_in_disks(counted, centres[sel], f * float(r), geographic=geo) for f in fs.radii}
        for k, i in enumerate(sel):
            if len(members[1.0][k]) < min_peaks:
                n_skipped += 1
                continue
            parts = []
            for f in fs.radii:
                idx = members[f][k]
                parts.append(disk_feature_vector(*(a[idx] for a in arrays), radius_m=f * float(r), feature_set=fs,
                                                 relative_elevation_convention=relative_elevation,
                                                 spacing_m=None if spacing is None else spacing[idx]))
            d = disks.iloc[i]
            if terrain is not None:
                from orokit.classify.terrain import terrain_matrix

                parts.append(terrain_matrix(dem, disks.iloc[[i]], fields=terrain)[0])
            vectors.append(np.concatenate(parts))
            rows.append({"label": label, "source": source,
                         "disk_id": int(d["disk_id"]) if "disk_id" in disks else int(i),
                         "x": float(d["x"]), "y": float(d["y"]), "radius_m": float(r),
                         "n_peaks": int(len(members[1.0][k]))})
    if n_skipped:
        warnings.warn(f"{n_skipped} of {len(disks)} disks{f' of {label!r}' if label else ''} have fewer than "
                      f"{min_peaks} peaks with prominence >= {min_prominence_m:g} m and were skipped "
                      f"(min_peaks / --min-peaks)", OrokitWarning, stacklevel=2)
    meta = pd.DataFrame(rows, columns=["label", "source", "disk_id", "x", "y", "radius_m", "n_peaks"])
    lon, lat = _lonlat(meta["x"].to_numpy(dtype=float), meta["y"].to_numpy(dtype=float), crs)
    meta.insert(5, "lon", lon)
    meta.insert(6, "lat", lat)
    feats = pd.DataFrame(np.vstack(vectors) if vectors else np.zeros((0, len(fs.columns))), columns=fs.columns)
    out = pd.concat([meta.reset_index(drop=True), feats], axis=1)
    out["label"] = out["label"].astype(object)
    out.attrs.update(_attrs(fs, radii, min_prominence_m, min_peaks, relative_elevation, exact_only))
    out.attrs["n_disks_sampled"] = int(len(disks))
    out.attrs["n_disks_skipped"] = int(n_skipped)
    out.attrs["label"] = label
    logger.info("%s: %d disks kept, %d skipped (< %d peaks)", label or "features", len(out), n_skipped, min_peaks)
    return out


#: per-peak columns, in the argument order of :func:`~orokit.sampling.feature_sets.disk_feature_vector`
_METRIC_INPUTS = ("elevation", "prominence", "saddle_distance_m", "saddle_direction_deg", "isolation_m",
                  "isolation_direction_deg")


def _attrs(fs: FeatureSet, radii: NDArray, min_prominence_m: float, min_peaks: int,
           relative_elevation: str, exact_only: bool) -> dict[str, Any]:
    u = np.unique(radii)
    return {"orokit_version": __version__, "feature_set": fs.to_dict(), "spec": fs.spec.to_dict(),
            "radius_m": float(u[0]) if len(u) == 1 else None, "min_prominence_m": float(min_prominence_m),
            "min_peaks": int(min_peaks), "relative_elevation": relative_elevation, "exact_only": bool(exact_only)}


def feature_set_of(features: pd.DataFrame) -> FeatureSet:
    """The FeatureSet recorded in a feature table (a table with only a HistogramSpec is the paper set)."""
    a = features.attrs
    if "feature_set" in a:
        return FeatureSet.from_dict(a["feature_set"])
    if "spec" in a:
        return dataclasses.replace(FeatureSet.paper(), spec=HistogramSpec.from_dict(a["spec"]))
    raise SchemaError("feature table has no recorded feature set (was it written by orokit features?)")


def feature_columns(features: pd.DataFrame) -> list[str]:
    """Feature columns of a table, from its recorded feature set."""
    return feature_set_of(features).columns


def _lonlat(x: NDArray, y: NDArray, crs: Any) -> tuple[NDArray, NDArray]:
    from pyproj import CRS, Transformer

    if crs is None or len(x) == 0:
        return np.full(len(x), np.nan), np.full(len(x), np.nan)
    c = CRS.from_user_input(crs)
    if c.is_geographic:
        return x, y
    try:
        if c.to_epsg() is None and "local" in c.name.lower():
            raise ValueError
        lon, lat = Transformer.from_crs(c, "EPSG:4326", always_xy=True).transform(x, y)
        return np.asarray(lon, float), np.asarray(lat, float)
    except Exception:  # local / engineering CRS: no real location
        return np.full(len(x), np.nan), np.full(len(x), np.nan)


def features_from_dem(dem: Any, *, radius_m: float, label: str | None = None, analysis: Any = None,
                      min_prominence_m: float = 30.0, min_peaks: int = 20, max_disks: int = 100,
                      separation: float = 0.5, feature_set: FeatureSet | None = None,
                      relative_elevation: RelativeElevation = RELATIVE_ELEVATION_DEFAULT,
                      exact_only: bool = False, rng: SeedLike = None) -> pd.DataFrame:
    """Feature table of one DEM: disks entirely inside its valid cells.

    Parameters
    ----------
    dem : xarray.DataArray
        Elevation in metres (:func:`orokit.io.dem.read_dem`).
    analysis : AnalysisResult, optional
        Result of :func:`orokit.analyze` on ``dem``; computed when omitted.
    Other parameters as :func:`feature_table` and :func:`orokit.sampling.disks.sample_disks_in_mask`.
    """
    if analysis is None:
        import orokit

        analysis = orokit.analyze(dem, min_prominence_m=min_prominence_m)
    valid = np.isfinite(np.asarray(dem.values, dtype=float))
    crs = dem.rio.crs
    disks = sample_disks_in_mask(valid, transform=dem.rio.transform(), radius_m=radius_m, crs=crs,
                                 separation=separation, max_disks=max_disks, rng=rng)
    if len(disks) == 0:
        warnings.warn(f"no disk of radius {radius_m:g} m fits inside the valid area of {label or 'the DEM'} "
                      f"({dem.shape[1]} x {dem.shape[0]} cells); use a smaller --radius", OrokitWarning, stacklevel=2)
    peaks = peak_geometry(analysis.peaks, crs=analysis.crs if analysis.crs is not None else crs)
    return feature_table(peaks, disks, feature_set=feature_set, min_prominence_m=min_prominence_m, min_peaks=min_peaks,
                         label=label, source=str(dem.attrs.get("source", label)), crs=peaks.crs,
                         relative_elevation=relative_elevation, exact_only=exact_only, dem=dem)


def features_from_region(peaks: pd.DataFrame, region: Any, *, radius_m: float, label: str | None = None,
                         region_crs: Any = None, min_prominence_m: float = 30.0, min_peaks: int = 20,
                         max_disks: int = 100, separation: float = 0.5, feature_set: FeatureSet | None = None,
                         relative_elevation: RelativeElevation = RELATIVE_ELEVATION_DEFAULT,
                         exact_only: bool = False, rng: SeedLike = None) -> pd.DataFrame:
    """Feature table of a region polygon over a peak list (the paper's world experiment).

    The polygon is reprojected to the peaks' CRS if both CRS are known. Disks lie inside
    the polygon eroded by R. A polygon that holds no peak at all (e.g. outside the
    list's coverage) gives an empty table and a warning.
    """
    from pyproj import CRS

    pcrs = getattr(peaks, "crs", None)
    geom = region
    if isinstance(region, (gpd.GeoDataFrame, gpd.GeoSeries)):
        region_crs = region_crs or region.crs
        geom = region.geometry.union_all() if hasattr(region.geometry, "union_all") else region.geometry.unary_union
    if region_crs is not None and pcrs is not None and not CRS.from_user_input(region_crs).equals(pcrs):
        geom = gpd.GeoSeries([geom], crs=region_crs).to_crs(pcrs).iloc[0]
        region_crs = pcrs
    crs = pcrs if pcrs is not None else region_crs
    disks = sample_disks_in_polygon(geom, radius_m=radius_m, crs=crs, separation=separation,
                                    max_disks=max_disks, rng=rng)
    if len(disks) and len(peaks):
        import shapely

        inside = shapely.contains_xy(shapely.make_valid(geom), peaks["x"].to_numpy(float), peaks["y"].to_numpy(float))
        if not inside.any():
            warnings.warn(f"region {label!r} contains none of the {len(peaks)} peaks: is it outside the peak "
                          f"list's coverage?", OrokitWarning, stacklevel=2)
    elif len(disks) == 0:
        warnings.warn(f"region {label!r} is smaller than a disk of radius {radius_m:g} m: 0 disks",
                      OrokitWarning, stacklevel=2)
    return feature_table(peaks, disks, feature_set=feature_set, min_prominence_m=min_prominence_m, min_peaks=min_peaks,
                         label=label, source=label, crs=crs, relative_elevation=relative_elevation,
                         exact_only=exact_only)


def concat_features(tables: Sequence[pd.DataFrame]) -> pd.DataFrame:
    """Concatenate feature tables made with the same feature set and parameters."""
    tables = [t for t in tables if t is not None]
    if not tables:
        raise InputError("no feature table to concatenate")
    ref = tables[0].attrs
    for t in tables[1:]:
        for k in ("feature_set", "spec", "min_prominence_m", "relative_elevation", "radius_m"):
            if t.attrs.get(k) != ref.get(k):
                raise SchemaError(f"feature tables differ in {k!r}: {ref.get(k)!r} vs {t.attrs.get(k)!r}; "
                                  f"compute all inputs with the same options")
    out = pd.concat(tables, ignore_index=True)
    out.attrs = dict(ref)
    out.attrs["n_disks_sampled"] = int(sum(t.attrs.get("n_disks_sampled", 0) for t in tables))
    out.attrs["n_disks_skipped"] = int(sum(t.attrs.get("n_disks_skipped", 0) for t in tables))
    out.attrs["skipped_by_label"] = {}
    for t in tables:
        if len(t) or t.attrs.get("n_disks_sampled"):
            lab = str(t["label"].iloc[0]) if len(t) else str(t.attrs.get("label"))
            out.attrs["skipped_by_label"][lab] = int(t.attrs.get("n_disks_skipped", 0))
    return out


def check_feature_table(features: pd.DataFrame, *, name: str = "feature table") -> list[str]:
    """Check a feature table's columns against its recorded feature set; returns the feature columns.

    Raises
    ------
    SchemaError
        No recorded feature set, missing columns, or a NaN / infinite value (named by
        column and row, so the table can be fixed or recomputed).
    """
    cols = feature_columns(features)
    missing = [c for c in ["label", "source", "x", "y", "radius_m"] + cols if c not in features]
    if missing:
        raise SchemaError(f"{name} lacks columns {missing[:5]}{'...' if len(missing) > 5 else ''}; recompute it "
                          f"with `orokit features`")
    X = features[cols].to_numpy(dtype=float)
    bad = ~np.isfinite(X)
    if bad.any():
        r, c = np.argwhere(bad)[0]
        raise SchemaError(f"{name} has {int(bad.sum())} NaN/infinite feature value(s); first: column {cols[c]!r}, "
                          f"row {int(r)} (value {X[r, c]!r}); recompute the table with `orokit features`")
    return cols
