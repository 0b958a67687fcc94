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
    from orokit.io.dem import read_dem

    tables = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OrokitWarning)  # skipped sparse disks are expected (andes-chile)
        for k, name in enumerate(DEMS):
            dem = read_dem(real_data(name), z_units="ft", cell_size=30.9 if name == "pyrenees" else 92.6)
            res = orokit.analyze(dem, min_prominence=30.0)
            tables.append(features_from_dem(dem, analysis=res, radius_m=10_000.0, label=name, rng=k))
    feats = concat_features(tables)
    counts = feats["label"].value_counts()
    # andes-chile has only a few disks with >= 20 peaks (the paper's code finds 3)
    assert set(DEMS) - set(counts.index) <= {"andes-chile"} and counts.max() <= 100 and len(feats) > 300
    ev = evaluate(feats, runs=10, feature_groups=False, small_classes="drop", rng=0)
    chance = 1.0 / len(DEMS)
    assert ev.mean_accuracy > 0.8 > 5 * chance  # measured: ~0.97 (random split), see the closing note
    sp = evaluate(feats, runs=5, split="spatial", feature_groups=False, small_classes="drop", rng=0)
    assert sp.mean_accuracy > 3 * chance  # measured: ~0.67 with a 2R buffer
    assert np.isfinite(ev.per_class["sahara"]) and ev.per_class["sahara"] > 0.8
