"""Trained region classifiers: the model object, its metadata and the checks on use.

The metadata records what is needed to use a model safely: format version, orokit /
scikit-learn / skops versions, disk radius, eps, min_peaks, relative-elevation
convention, the feature set (bins, radii, summaries), feature names, classes, the
calibration (temperatures and "unknown" thresholds), evaluation summary and the sha256 of the training feature table.
Files (skops archive with the metadata inside, readable sidecar, checksums, refusal of
corrupt or pickled files) are handled by :mod:`orokit.io.model_io`. A different orokit
or scikit-learn version only warns; features computed otherwise are refused
(:func:`check_features`).
"""
from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from orokit import __version__
from orokit._typing import PathLike
from orokit.classify.calibration import Calibration
from orokit.errors import OrokitWarning, SchemaError
from orokit.io.model_io import MODEL_FORMAT, load_model_file, metadata_path, save_model_file
from orokit.sampling.feature_sets import FeatureSet

__all__ = ["MODEL_FORMAT", "RegionModel", "model_metadata", "save_model", "load_model", "check_features",
           "metadata_path"]


@dataclasses.dataclass(frozen=True)
class RegionModel:
    """A trained region classifier and its metadata."""

    pipeline: Any
    metadata: dict[str, Any]

    @property
    def feature_set(self) -> FeatureSet:
        return FeatureSet.from_dict(self.metadata["feature_set"])

    @property
    def radius_m(self) -> float:
        return float(self.metadata["radius_m"])

    @property
    def classes(self) -> list[str]:
        return list(self.metadata["classes"])

    @property
    def feature_names(self) -> list[str]:
        return list(self.metadata["feature_names"])

    @property
    def calibration(self) -> Calibration:
        """Temperatures and 'unknown' thresholds (identity for models saved without them; their
        terrain threshold is then the metadata's ``unknown_threshold``)."""
        cal = Calibration.from_dict(self.metadata.get("calibration"))
        if not self.metadata.get("calibration"):
            cal = dataclasses.replace(cal, terrain_threshold=float(self.metadata.get("unknown_threshold") or 0.0))
        return cal

    def predict_proba(self, X: Any) -> Any:
        """Calibrated class probabilities of feature rows (columns: :attr:`classes`)."""
        return self.calibration.disk_proba(self.pipeline.predict_proba(X))


def model_metadata(pipeline: Any, features: pd.DataFrame, *, evaluation: dict[str, Any] | None = None,
                   features_sha256: str | None = None, extra: dict[str, Any] | None = None) -> dict[str, Any]:
    """Metadata of a pipeline trained on ``features`` (a feature table with attrs)."""
    import sklearn
    import skops

    from orokit.classify.features import feature_set_of

    a = features.attrs
    fs = feature_set_of(features)
    md = {
        "format": MODEL_FORMAT, "orokit_version": __version__, "sklearn_version": sklearn.__version__,
        "skops_version": skops.__version__, "radius_m": a.get("radius_m"),
        "min_prominence_m": a.get("min_prominence_m"), "min_peaks": a.get("min_peaks"),
        "relative_elevation": a.get("relative_elevation"), "exact_only": a.get("exact_only", False),
        "feature_set": fs.to_dict(), "feature_names": fs.columns,
        "classes": [str(c) for c in pipeline.classes_],
        "n_training_disks": {str(k): int(v) for k, v in features["label"].astype(str).value_counts().items()},
        "features_sha256": features_sha256, "evaluation": evaluation or {},
    }
    md.update(extra or {})
    return md


def save_model(pipeline: Any, path: PathLike, metadata: dict[str, Any]) -> Path:
    """Save ``pipeline`` and its metadata (from :func:`model_metadata`) to ``path`` (see :mod:`orokit.io.model_io`)."""
    if "format" not in metadata or "feature_names" not in metadata:
        raise SchemaError("model metadata must come from model_metadata(...)")
    return save_model_file(pipeline, metadata, path)


def load_model(path: PathLike, *, check_hash: bool = True) -> RegionModel:
    """Load a model saved by :func:`save_model`, refusing anything it cannot verify.

    File checks (checksum, corrupt or pickled files, untrusted types, an edited sidecar)
    are those of :func:`orokit.io.model_io.load_model_file`; then the estimator must agree
    with the metadata (classes, number of features). Another orokit or scikit-learn
    version only warns.

    Raises
    ------
    InputError
        Missing, corrupt or replaced files, untrusted types.
    SchemaError
        Another model format version, an edited sidecar, or metadata that contradicts the estimator.
    """
    import sklearn

    pipeline, md = load_model_file(path, check_hash=check_hash)
    for key, have in (("orokit_version", __version__), ("sklearn_version", sklearn.__version__)):
        if md.get(key) != have:
            warnings.warn(f"model {path} was saved with {key.split('_')[0]} {md.get(key)}, this is {have}; "
                          f"predictions may differ, retrain if in doubt", OrokitWarning, stacklevel=2)
    classes = [str(c) for c in getattr(pipeline, "classes_", [])]
    if classes != list(md.get("classes", [])):
        raise SchemaError(f"model {path}: estimator classes {classes} differ from metadata {md.get('classes')}")
    n_in = getattr(pipeline, "n_features_in_", None)
    if n_in is not None and n_in != len(md.get("feature_names", [])):
        raise SchemaError(f"model {path}: estimator expects {n_in} features, metadata lists "
                          f"{len(md.get('feature_names', []))}")
    return RegionModel(pipeline, md)


def check_features(model: RegionModel, features: pd.DataFrame) -> None:
    """Raise :class:`SchemaError` unless ``features`` were computed like the model's training features."""
    a = features.attrs
    problems = []
    from orokit.classify.features import feature_set_of

    try:
        fs = feature_set_of(features)
    except SchemaError:
        fs = None
    if fs is not None and fs != model.feature_set:
        problems.append(f"feature set {fs.name!r} differs from the model's {model.feature_set.name!r} "
                        f"(radii, bins or summaries)")
    missing = [c for c in model.feature_names if c not in features]
    if missing:
        problems.append(f"missing feature columns {missing[:5]}")
    for key in ("radius_m", "min_prominence_m", "relative_elevation"):
        want, have = model.metadata.get(key), a.get(key)
        if have is not None and want is not None and (
                (isinstance(want, float) and not np.isclose(float(have), want)) or
                (not isinstance(want, float) and have != want)):
            problems.append(f"{key} is {have!r}, the model was trained with {want!r}")
    if problems:
        raise SchemaError("features do not match the model: " + "; ".join(problems) +
                          ". Recompute them with the model's parameters (orokit classify does this from a DEM "
                          "or peak list).")
