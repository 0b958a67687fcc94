"""Classify disks and whole inputs with a trained :class:`~orokit.classify.model.RegionModel`."""
from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pandas as pd

from orokit._typing import SeedLike
from orokit.classify.model import RegionModel, check_features
from orokit.errors import InputError, SchemaError


#: answer when the best class is not confident enough (see :func:`predict_regions`)
UNKNOWN = "unknown"


@dataclasses.dataclass
class Prediction:
    """Per-disk predictions and the terrain-level answer of one input."""

    disks: pd.DataFrame  # disk_id, x, y, n_peaks, predicted, answer, confidence, proba_<class>... (calibrated)
    label: str | None  # best class, or UNKNOWN when below the terrain threshold (None without disks)
    probabilities: dict[str, float]  # calibrated terrain posterior from the disks' summed log-probabilities
    votes: dict[str, int]  # disks predicted per class
    best: str | None = None  # best class even when the answer is UNKNOWN
    confidence: float = float("nan")  # mean over disks of the best class's calibrated probability
    threshold: float | None = None  # confidence below which the answer is UNKNOWN
    disk_threshold: float | None = None  # a disk's top probability below which its answer is UNKNOWN

    @property
    def unknown_disks(self) -> int:
        """Disks whose own answer is UNKNOWN."""
        return int((self.disks["answer"] == UNKNOWN).sum()) if "answer" in self.disks else 0

    def to_dict(self) -> dict[str, Any]:
        return {"label": self.label, "best": self.best, "confidence": self.confidence,
                "unknown_threshold": self.threshold, "disk_unknown_threshold": self.disk_threshold,
                "probabilities": self.probabilities, "votes": self.votes, "n_disks": int(len(self.disks)),
                "unknown_disks": self.unknown_disks,
                "disks": self.disks.replace({np.nan: None}).to_dict(orient="records")}


def predict_regions(model: RegionModel, features: pd.DataFrame, *, threshold: float | None = None,
                    disk_threshold: float | None = None) -> Prediction:
    """Predict the region of every disk of a feature table and of the whole input.

    Disk probabilities are calibrated (:attr:`RegionModel.calibration`, temperature scaling
    fitted on the spatial hold-out). The terrain label maximises the disks' summed
    calibrated log-probability; ``probabilities`` is the calibrated terrain posterior. The
    answer is :data:`UNKNOWN` when the mean probability of that class over the disks is
    below ``threshold`` (default: the model's terrain threshold, chosen on the spatial
    hold-out; ``0`` never answers unknown); a disk's ``answer`` is :data:`UNKNOWN` when its
    top probability is below ``disk_threshold`` (default: the model's; ``0`` never).
    ``votes`` gives the hard-vote counts of the best classes.
    """
    check_features(model, features)
    classes = model.classes
    cal = model.calibration
    if threshold is None:
        threshold = cal.terrain_threshold
    if disk_threshold is None:
        disk_threshold = cal.disk_threshold
    if len(features) == 0:
        return Prediction(pd.DataFrame(columns=["disk_id", "x", "y", "n_peaks", "predicted", "answer", "confidence"]),
                          None, {c: float("nan") for c in classes}, {c: 0 for c in classes}, threshold=threshold,
                          disk_threshold=disk_threshold)
    cols = model.feature_names
    X = features[cols].to_numpy(dtype=float)
    bad = ~np.isfinite(X)
    if bad.any():
        r, c = np.argwhere(bad)[0]
        raise SchemaError(f"features hold {int(bad.sum())} NaN/infinite value(s); first: column {cols[c]!r}, row "
                          f"{int(r)}; recompute them with `orokit features`")
    proba = model.predict_proba(X)
    pred = np.asarray(classes)[np.argmax(proba, axis=1)]
    disks = features[[c for c in ("label", "source", "disk_id", "x", "y", "lon", "lat", "radius_m", "n_peaks")
                      if c in features]].copy().reset_index(drop=True)
    disks["predicted"] = pred
    disks["confidence"] = proba.max(axis=1)
    disks["answer"] = np.where(disks["confidence"] < float(disk_threshold), UNKNOWN, pred)
    for k, c in enumerate(classes):
        disks[f"proba_{c}"] = proba[:, k]
    logp = np.log(proba).sum(axis=0)
    post = cal.terrain_posterior(logp)
    k_best = int(np.argmax(logp))
    best = classes[k_best]
    confidence = float(proba[:, k_best].mean())
    label = UNKNOWN if confidence < float(threshold) else best
    votes = {c: int(np.sum(pred == c)) for c in classes}
    return Prediction(disks, label, {c: float(v) for c, v in zip(classes, post)}, votes, best, confidence,
                      float(threshold), float(disk_threshold))


def classify_input(model: RegionModel, source: Any, *, z_units: str | None = None, cell_size_m: float | None = None,
                   region: Any = None, min_peaks: int | None = None, isolation: Any = None,
                   threshold: float | None = None, disk_threshold: float | None = None, dem: Any = None,
                   rng: SeedLike = 0) -> Prediction:
    """Compute features of a DEM, ``orokit analyze`` folder or peak list (or of ``dem``, an
    opened DEM) with the model's parameters (radius, eps, feature set) and classify them."""
    from orokit.classify.features import features_from_dem
    from orokit.classify.inputs import default_label, features_for_input

    md = model.metadata
    eps = md.get("min_prominence_m")
    if min_peaks is None:
        min_peaks = md.get("min_peaks")
    kw: dict[str, Any] = dict(radius_m=model.radius_m, min_prominence_m=float(eps if eps is not None else 30.0),
              min_peaks=int(min_peaks if min_peaks is not None else 20), feature_set=model.feature_set,
              relative_elevation=md.get("relative_elevation") or "minmax", rng=rng)
    if dem is not None:
        feats = features_from_dem(dem, label=default_label(source), **kw)
    else:
        feats = features_for_input(source, z_units=z_units, cell_size_m=cell_size_m, region=region, isolation=isolation,
                                   **kw)
    if len(feats) == 0:
        raise InputError(f"no usable disk in {source}: every disk of radius {model.radius_m:g} m had fewer than "
                         f"{feats.attrs.get('min_peaks')} peaks or did not fit in the data; lower --min-peaks")
    return predict_regions(model, feats, threshold=threshold, disk_threshold=disk_threshold)


def disk_map(prediction: Prediction, *, crs: Any, n_vertices: int = 64) -> Any:
    """Every disk of ``prediction`` as a polygon (in ``crs``) with its class probabilities.

    Columns: disk_id, x, y, radius_m, n_peaks, predicted, answer (the prediction or
    ``unknown``), confidence (the top calibrated probability), ``proba_<class>`` (summing
    to 1 per disk) and the polygon. On a
    geographic CRS each polygon is the geodesic circle of radius R (WGS84), else a
    Euclidean circle; ``n_vertices`` points each.
    """
    import geopandas as gpd
    import shapely

    from orokit.classify.peaklist import is_geographic

    d = prediction.disks.copy()
    pcols = [c for c in d.columns if c.startswith("proba_")]
    d["confidence"] = d[pcols].to_numpy(float).max(axis=1) if len(d) and pcols else np.zeros(len(d))
    x, y = d["x"].to_numpy(float), d["y"].to_numpy(float)
    r = d["radius_m"].to_numpy(float) if "radius_m" in d else np.full(len(d), np.nan)
    az = np.linspace(0.0, 360.0, n_vertices, endpoint=False)
    polys = []
    if is_geographic(crs):
        from orokit.geodesy import WGS84 as geod

        for xi, yi, ri in zip(x, y, r):
            lon, lat, _ = geod.fwd(np.full(n_vertices, xi), np.full(n_vertices, yi), az, np.full(n_vertices, ri))
            polys.append(shapely.Polygon(np.column_stack([lon, lat])))
    else:
        t = np.radians(az)
        for xi, yi, ri in zip(x, y, r):
            polys.append(shapely.Polygon(np.column_stack([xi + ri * np.cos(t), yi + ri * np.sin(t)])))
    keep = [c for c in ("disk_id", "x", "y", "lon", "lat", "radius_m", "n_peaks", "predicted", "answer", "confidence")
            if c in d] + pcols
    return gpd.GeoDataFrame(d[keep].reset_index(drop=True), geometry=polys, crs=crs)
