"""End-to-end on the 13 real DEMs: analysis -> disks -> features -> repeated training runs."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

DEMS = ["alaska", "andes-aconcagua", "andes-chile", "appalachians", "gobi", "highlands", "himalaya-annapurna",
        "himalaya-everest", "karakoram", "norway", "pyrenees", "rockies", "sahara"]


@pytest.mark.realdata
@pytest.mark.slow
def test_real_dems_classify_well_above_chance(real_data):
    import orokit
    from orokit.classify.features import concat_features, features_from_dem
    from orokit.classify.train import evaluate
    from orokit.errors import OrokitWarning
    from orokit.data import open_dataset_dem

    tables = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OrokitWarning)  # skipped sparse disks are expected (andes-chile)
        for k, name in enumerate(DEMS):
            real_data(name)  # fails in CI / skips elsewhere when the data cannot be obtained
            dem = open_dataset_dem(name)  # units and cell size from the manifest
            res = orokit.analyze(dem, min_prominence_m=30.0)
            tables.append(features_from_dem(dem, analysis=res, radius_m=10_000.0, label=name, rng=k))
    feats = concat_features(tables)
    counts = feats["label"].value_counts()
    # andes-chile has only a few disks with >= 20 peaks (the paper's code finds 3)
    assert set(DEMS) - set(counts.index) <= {"andes-chile"} and counts.max() <= 100 and len(feats) > 300
    ev = evaluate(feats, runs=10, feature_groups=False, small_classes="drop", rng=0)
    assert ev.mean_accuracy > 0.9  # measured: ~0.97 (random split); chance is 1/13
    sp = evaluate(feats, runs=5, split="spatial", feature_groups=False, small_classes="drop", rng=0)
    assert np.isfinite(sp.mean_accuracy) and sp.mean_accuracy > 0.5  # measured: ~0.67 with a 2R buffer
    # spatial k-fold: every disk held out once with its 10 km block, training disks > 20 km away
    bl = evaluate(feats, runs=1, split="blocks", block_m=10_000.0, feature_groups=False, small_classes="drop", rng=0)
    assert bl.params["untested_disks_per_run"] < 0.05 * len(feats)
    assert bl.mean_accuracy > 0.65  # measured: 0.80 on the report's disks (orometry features, one run)
    assert np.isfinite(ev.per_class["sahara"]) and ev.per_class["sahara"] > 0.8
