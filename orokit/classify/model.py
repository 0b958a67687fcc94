"""Trained region classifiers on disk: skops file + JSON metadata sidecar.

``MODEL.skops`` holds the scikit-learn Pipeline, saved with :mod:`skops.io` (never
pickle: a downloaded pickle can run arbitrary code). ``MODEL.skops.json`` holds the
metadata needed to use it safely: format version, orokit / scikit-learn / skops
versions, disk radius, eps, min_peaks, relative-elevation convention, the
HistogramSpec, feature names, classes, evaluation summary, sha256 of the model file
and of the training feature table.

Loading checks, in order: the sidecar exists and has this format version; the
sha256 of the model file matches; the skops file contains only trusted types
(scikit-learn forests and numpy); the classes and number of features of the loaded
estimator agree with the metadata. A different orokit or scikit-learn version only
warns (trees may still load); a mismatch of features with a feature table is an error
(:func:`check_features`).
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from orokit import __version__
from orokit._typing import PathLike
from orokit.errors import InputError, OrokitWarning, SchemaError
from orokit.io.atomic import write_bytes_atomic
from orokit.sampling.histograms import HistogramSpec

MODEL_FORMAT = "orokit-region-classifier/1"
_TRUSTED_PREFIXES = ("sklearn.", "numpy.", "builtins.")


def sha256_file(path: PathLike) -> str:
    """Hex sha256 of a file."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


@dataclasses.dataclass(frozen=True)
class RegionModel:
    """A trained region classifier and its metadata."""

    pipeline: Any
    metadata: dict[str, Any]

    @property
    def spec(self) -> HistogramSpec:
        return HistogramSpec.from_dict(self.metadata["spec"])

    @property
    def radius_m(self) -> float:
        return float(self.metadata["radius_m"])

    @property
    def classes(self) -> list[str]:
        return list(self.metadata["classes"])

    @property
    def feature_names(self) -> list[str]:
        return list(self.metadata["feature_names"])


def model_metadata(pipeline: Any, features: pd.DataFrame, *, evaluation: dict[str, Any] | None = None,
                   features_sha256: str | None = None, extra: dict[str, Any] | None = None) -> dict[str, Any]:
    """Metadata of a pipeline trained on ``features`` (a feature table with attrs)."""
    import sklearn
    import skops

    a = features.attrs
    spec = HistogramSpec.from_dict(a["spec"])
    md = {
        "format": MODEL_FORMAT, "orokit_version": __version__, "sklearn_version": sklearn.__version__,
        "skops_version": skops.__version__, "radius_m": a.get("radius_m"),
        "min_prominence_m": a.get("min_prominence_m"), "min_peaks": a.get("min_peaks"),
        "relative_elevation": a.get("relative_elevation"), "exact_only": a.get("exact_only", False),
        "spec": spec.to_dict(), "feature_names": spec.columns,
        "classes": [str(c) for c in pipeline.classes_],
        "n_training_disks": {str(k): int(v) for k, v in features["label"].astype(str).value_counts().items()},
        "features_sha256": features_sha256, "evaluation": evaluation or {},
    }
    md.update(extra or {})
    return md


def metadata_path(path: PathLike) -> Path:
    """Sidecar path of a model file: ``MODEL.skops`` -> ``MODEL.skops.json``."""
    p = Path(path)
    return p.with_name(p.name + ".json")


def save_model(pipeline: Any, path: PathLike, metadata: dict[str, Any]) -> Path:
    """Save ``pipeline`` with skops to ``path`` and its metadata (plus sha256) beside it, atomically."""
    import skops.io as sio

    path = Path(path)
    if "format" not in metadata or "spec" not in metadata:
        raise SchemaError("model metadata must come from model_metadata(...)")
    blob = sio.dumps(pipeline)
    md = dict(metadata)
    md["sha256"] = hashlib.sha256(blob).hexdigest()
    write_bytes_atomic(path, blob)
    write_bytes_atomic(metadata_path(path), json.dumps(md, indent=2, sort_keys=True, default=str).encode())
    return path


def load_model(path: PathLike, *, check_hash: bool = True) -> RegionModel:
    """Load a model saved by :func:`save_model`, refusing anything it cannot verify.

    Raises
    ------
    InputError
        Missing file or sidecar, checksum mismatch, untrusted types in the skops file.
    SchemaError
        Another model format version, or metadata that contradicts the estimator.
    """
    import skops.io as sio

    path = Path(path)
    mpath = metadata_path(path)
    if not path.exists():
        raise InputError(f"model file {path} does not exist; train one with `orokit train`")
    if not mpath.exists():
        raise InputError(f"model {path} has no metadata file {mpath.name}; orokit only loads models saved by "
                         f"`orokit train` (skops + metadata)")
    try:
        md = json.loads(mpath.read_text())
    except json.JSONDecodeError as exc:
        raise SchemaError(f"model metadata {mpath} is not valid JSON: {exc}") from exc
    if md.get("format") != MODEL_FORMAT:
        raise SchemaError(f"model {path} has format {md.get('format')!r} (orokit {md.get('orokit_version')}); this "
                          f"orokit {__version__} reads {MODEL_FORMAT!r}: retrain with `orokit train`")
    blob = path.read_bytes()
    if check_hash and md.get("sha256") != hashlib.sha256(blob).hexdigest():
        raise InputError(f"model {path} does not match the sha256 in {mpath.name} (expected {md.get('sha256')}, "
                         f"got {hashlib.sha256(blob).hexdigest()}): corrupted or replaced file")
    untrusted = sio.get_untrusted_types(data=blob)
    bad = [t for t in untrusted if not t.startswith(_TRUSTED_PREFIXES)]
    if bad:
        raise InputError(f"model {path} contains types that are not scikit-learn/numpy: {bad}; refusing to load")
    pipeline = sio.loads(blob, trusted=untrusted)
    import sklearn

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
    if "spec" in a and HistogramSpec.from_dict(a["spec"]) != model.spec:
        problems.append("histogram bins differ")
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
