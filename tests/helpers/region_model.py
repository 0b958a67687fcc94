"""A small region model trained in the tests (instead of the 8.5 MB build product ``models/regions-10km.skops``).

Two made-up regions of fractal noise, ``hills`` (low, smooth) and ``peaks`` (high, rough), at 100 m cells:
their disks' terrain features tell them apart, and the model is a real forest with the metadata
``orokit train`` writes (feature set, radius, eps, classes).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

STYLES = {"hills": dict(base=600.0, amplitude=300.0, largest_m=3_000.0, persistence=0.6),
          "peaks": dict(base=1800.0, amplitude=1500.0, largest_m=8_000.0, persistence=0.65)}


def style_dem(style: str, *, size_km: float = 50.0, cell_m: float = 100.0, rng: int = 0) -> Any:
    """A square DEM (UTM 33N, metres) of one of :data:`STYLES`."""
    import numpy as np

    from helpers.dems import build_dem
    from orokit.raster.noise import fractal_noise

    kw = dict(STYLES[style])
    n = int(round(size_km * 1000.0 / cell_m))
    z = kw.pop("base") + fractal_noise((n, n), cell_m, rng=rng, **kw)
    return build_dem(z.astype(np.float32), res=cell_m)


def train_region_model(path: Path, *, radius_m: float = 10_000.0, feature_set: str = "terrain",
                       trees: int = 30) -> Path:
    """Train and save (``save_model``) a model of the two styles at ``radius_m``; returns ``path``."""
    from orokit.classify.features import concat_features, features_from_dem
    from orokit.classify.model import model_metadata, save_model
    from orokit.classify.train import train_classifier
    from orokit.sampling.feature_sets import FeatureSet

    fs = FeatureSet.named(feature_set)
    tables = [features_from_dem(style_dem(name, rng=k), radius_m=radius_m, label=name, max_disks=12,
                                feature_set=fs, rng=k) for k, name in enumerate(STYLES)]
    feats = concat_features(tables)
    model = train_classifier(feats, n_estimators=trees, classifier="et", n_jobs=1, rng=0)
    return save_model(model, path, model_metadata(model, feats))
