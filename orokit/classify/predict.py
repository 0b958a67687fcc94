"""Classify disks and whole inputs with a trained :class:`~orokit.classify.model.RegionModel`."""
from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pandas as pd

from orokit._typing import SeedLike
from orokit.classify.model import RegionModel, check_features
from orokit.errors import InputError


@dataclasses.dataclass
class Prediction:
    """Per-disk predictions and the overall vote of one input."""

    disks: pd.DataFrame  # disk_id, x, y, n_peaks, predicted, proba_<class>...
    label: str | None  # class with the highest mean probability (None without disks)
    probabilities: dict[str, float]  # mean over disks
    votes: dict[str, int]  # disks predicted per class

    def to_dict(self) -> dict[str, Any]:
        return {"label": self.label, "probabilities": self.probabilities, "votes": self.votes,
                "n_disks": int(len(self.disks)),
                "disks": self.disks.replace({np.nan: None}).to_dict(orient="records")}


def predict_regions(model: RegionModel, features: pd.DataFrame) -> Prediction:
    """Predict the region of every disk of a feature table and vote.

    The overall label maximises the mean class probability over the disks (soft vote);
    ``votes`` also gives the hard-vote counts.
    """
    check_features(model, features)
    classes = model.classes
    if len(features) == 0:
        return Prediction(pd.DataFrame(columns=["disk_id", "x", "y", "n_peaks", "predicted"]), None,
                          {c: float("nan") for c in classes}, {c: 0 for c in classes})
    X = features[model.feature_names].to_numpy(dtype=float)
    proba = model.pipeline.predict_proba(X)
    pred = np.asarray(classes)[np.argmax(proba, axis=1)]
    disks = features[[c for c in ("label", "source", "disk_id", "x", "y", "lon", "lat", "n_peaks")
                      if c in features]].copy().reset_index(drop=True)
    disks["predicted"] = pred
    for k, c in enumerate(classes):
        disks[f"proba_{c}"] = proba[:, k]
    mean = proba.mean(axis=0)
    votes = {c: int(np.sum(pred == c)) for c in classes}
    return Prediction(disks, classes[int(np.argmax(mean))], {c: float(m) for c, m in zip(classes, mean)}, votes)


def classify_input(model: RegionModel, source: Any, *, z_units: str | None = None, cell_size: float | None = None,
                   region: Any = None, min_peaks: int | None = None, isolation: Any = None,
                   rng: SeedLike = 0) -> Prediction:
    """Compute features of a DEM, ``orokit analyze`` folder or peak list with the model's
    parameters (radius, eps, bins) and classify them."""
    from orokit.classify.inputs import features_for_input

    md = model.metadata
    eps = md.get("min_prominence_m")
    if min_peaks is None:
        min_peaks = md.get("min_peaks")
    feats = features_for_input(
        source, radius_m=model.radius_m, min_prominence_m=float(eps if eps is not None else 30.0),
        min_peaks=int(min_peaks if min_peaks is not None else 20), spec=model.spec,
        relative_elevation=md.get("relative_elevation") or "minmax", z_units=z_units, cell_size=cell_size,
        region=region, isolation=isolation, rng=rng)
    if len(feats) == 0:
        raise InputError(f"no usable disk in {source}: every disk of radius {model.radius_m:g} m had fewer than "
                         f"{feats.attrs.get('min_peaks')} peaks or did not fit in the data; lower --min-peaks")
    return predict_regions(model, feats)
