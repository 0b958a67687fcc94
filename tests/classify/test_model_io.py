"""Model and feature-table files: checksums cover the metadata, corrupt files are refused (issue 15)."""
from __future__ import annotations

import hashlib
import json
import pickle

import numpy as np
import pytest
import shapely
from click.testing import CliRunner

from orokit.classify.features import concat_features, feature_table
from orokit.classify.model import load_model, metadata_path, model_metadata, save_model
from orokit.classify.peaklist import peak_geometry
from orokit.classify.predict import predict_regions
from orokit.classify.train import evaluate, train_classifier
from orokit.cli.main import cli
from orokit.errors import InputError, SchemaError
from orokit.io.model_io import read_feature_table, write_feature_table
from orokit.sampling.disks import sample_disks_in_polygon
from orokit.sampling.feature_sets import FeatureSet

STYLES = {"rolling": dict(prom_scale=60.0, saddle_scale_m=700.0), "alpine": dict(prom_scale=350.0,
          saddle_scale_m=2500.0)}


def _feats(feature_set=None):
    from helpers.classify_synth import make_peaks

    tables = []
    for k, (name, kw) in enumerate(STYLES.items()):
        p = peak_geometry(make_peaks(800, rng=30 + k, **kw))
        d = sample_disks_in_polygon(shapely.box(0, -60_000, 60_000, 0), radius_m=10_000, rng=k, max_disks=12)
        tables.append(feature_table(p, d, label=name, source=name, feature_set=feature_set))
    return concat_features(tables)


@pytest.fixture(scope="module")
def feats():
    return _feats()


@pytest.fixture
def model_path(feats, tmp_path):
    model = train_classifier(feats, n_estimators=5, rng=0)
    return save_model(model, tmp_path / "m.skops", model_metadata(model, feats))


def _resign(path):
    """Make the sidecar's sha256 match the (altered) model file, as an attacker or a careless copy would."""
    mp = metadata_path(path)
    md = json.loads(mp.read_text())
    md["sha256"] = hashlib.sha256(path.read_bytes()).hexdigest()
    mp.write_text(json.dumps(md))


@pytest.mark.parametrize("edit", [
    lambda md: md.update(feature_names=list(reversed(md["feature_names"]))),
    lambda md: md.update(radius_m=5000.0),
    lambda md: md["feature_set"]["spec"]["features"][7].update(edges=[2 * e for e in
                                                                      md["feature_set"]["spec"]["features"][7]["edges"]]),
    lambda md: md.update(unknown_threshold=0.9),
])
def test_edited_sidecar_is_refused(model_path, edit):
    mp = metadata_path(model_path)
    md = json.loads(mp.read_text())
    edit(md)
    mp.write_text(json.dumps(md))  # the sha256 of the model file still matches
    with pytest.raises(SchemaError, match="sidecar was edited"):
        load_model(model_path)


def test_corrupt_models_are_refused(model_path):
    blob = model_path.read_bytes()
    model_path.write_bytes(blob[: len(blob) // 2])
    _resign(model_path)
    with pytest.raises(InputError, match="corrupt or truncated"):
        load_model(model_path)
    model_path.write_bytes(b"")
    _resign(model_path)
    with pytest.raises(InputError, match="empty"):
        load_model(model_path)
    model_path.write_bytes(b"not a model at all")
    _resign(model_path)
    with pytest.raises(InputError, match="not a skops archive"):
        load_model(model_path)


class _Boom:
    """Unpickling this object would create a file: the proof that a pickle was executed."""

    def __init__(self, path):
        self.path = path

    def __reduce__(self):
        return (open, (self.path, "w"))


def test_pickle_renamed_skops_is_never_executed(model_path, tmp_path):
    witness = tmp_path / "executed"
    model_path.write_bytes(pickle.dumps(_Boom(str(witness))))
    _resign(model_path)
    with pytest.raises(InputError, match="pickle"):
        load_model(model_path)
    assert not witness.exists()
    res = CliRunner().invoke(cli, ["classify", str(model_path), str(model_path)])
    assert res.exit_code == 1 and "pickle" in res.output and "Traceback" not in res.output
    assert not witness.exists()


def test_model_refuses_features_of_another_set(feats, model_path):
    model = load_model(model_path)
    assert model.feature_set == FeatureSet.orometry()
    paper = _feats(FeatureSet.paper())
    with pytest.raises(SchemaError, match="feature set 'paper' differs"):
        predict_regions(model, paper)
    assert predict_regions(model, feats).label in STYLES


def test_nan_and_inf_features_are_refused(feats, tmp_path):
    col = FeatureSet.orometry().columns[3]
    for bad in (np.nan, np.inf):
        f = feats.copy()
        f.attrs = dict(feats.attrs)
        f.loc[5, col] = bad
        with pytest.raises(SchemaError, match=f"column '{col}', row 5"):
            evaluate(f, runs=1, feature_groups=False)
        with pytest.raises(SchemaError, match=f"column '{col}', row 5"):
            train_classifier(f, n_estimators=2)
        path = write_feature_table(f, tmp_path / "f.parquet")
        res = CliRunner().invoke(cli, ["train", str(path), "-o", str(tmp_path / "m.skops"), "--runs", "1",
                                       "--no-progress", "--overwrite"])
        assert res.exit_code == 1 and col in res.output and "row 5" in res.output, res.output
        assert "Traceback" not in res.output and not (tmp_path / "m.skops").exists()
    g = read_feature_table(write_feature_table(feats, tmp_path / "ok.parquet"))
    assert g.attrs["feature_set"] == feats.attrs["feature_set"] and len(g) == len(feats)
