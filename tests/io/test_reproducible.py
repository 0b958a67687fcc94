"""Byte-reproducible outputs: canonical skops archives and portable paths."""
from __future__ import annotations

import io
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest

from orokit.data import portable_path
from orokit.io.reproducible import ZIP_EPOCH, canonical_skops


def _model(seed: int = 0):
    from sklearn.ensemble import RandomForestClassifier
    from sklearn.pipeline import Pipeline
    from sklearn.preprocessing import StandardScaler

    rng = np.random.default_rng(1)
    x = rng.normal(size=(120, 4))
    y = (x[:, 0] + 0.3 * x[:, 1] > 0).astype(int)
    return Pipeline([("scale", StandardScaler()),
                     ("rf", RandomForestClassifier(n_estimators=8, random_state=seed, n_jobs=2))]).fit(x, y), x


def test_same_model_same_bytes_and_loads_back():
    import skops.io as sio

    m1, x = _model()
    raw1 = sio.dumps(m1)
    time.sleep(2.1)  # zip timestamps have a 2 s resolution
    m2, _ = _model()
    raw2 = sio.dumps(m2)
    assert raw1 != raw2  # what this module fixes: skops bytes depend on memory addresses and the clock
    a, b = canonical_skops(raw1), canonical_skops(raw2)
    assert a == b
    assert canonical_skops(a) == a  # idempotent
    back = sio.loads(a, trusted=sio.get_untrusted_types(data=a))
    np.testing.assert_array_equal(back.predict_proba(x), m1.predict_proba(x))
    names = zipfile.ZipFile(io.BytesIO(a)).namelist()
    assert names[0] == "schema.json" and all(i.date_time == ZIP_EPOCH for i in zipfile.ZipFile(io.BytesIO(a)).infolist())


def test_another_seed_other_bytes():
    import skops.io as sio

    assert canonical_skops(sio.dumps(_model(0)[0])) != canonical_skops(sio.dumps(_model(1)[0]))


def test_portable_path(monkeypatch, tmp_path):
    cache = tmp_path / "cache"
    (cache / "dems").mkdir(parents=True)
    monkeypatch.setenv("OROKIT_DATA_DIR", str(cache))
    monkeypatch.delenv("OROKIT_DATA_MIRROR", raising=False)
    assert portable_path(cache / "dems" / "gobi.png") == "dems/gobi.png"
    monkeypatch.chdir(tmp_path)
    assert portable_path(tmp_path / "reports" / "x.json") == "reports/x.json"
    assert portable_path("a/b.tif") == "a/b.tif"
    assert portable_path(None) == "" and portable_path("") == ""
    outside = Path("/nonexistent-root/x.tif")
    assert portable_path(outside) == outside.as_posix()
