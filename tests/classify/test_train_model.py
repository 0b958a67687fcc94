from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
import shapely
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from orokit.classify.features import concat_features, feature_set_of, feature_table
from orokit.io.model_io import write_feature_table as write_features
from orokit.classify.model import load_model, metadata_path, model_metadata, save_model
from orokit.classify.peaklist import peak_geometry
from orokit.classify.predict import predict_regions
from orokit.classify.train import check_classes, evaluate, random_split, spatial_split, train_classifier
from orokit.cli.main import cli
from orokit.errors import InputError, OrokitWarning, SchemaError
from orokit.sampling.disks import sample_disks_in_polygon

STYLES = {"rolling": dict(prom_scale=60.0, saddle_scale_m=700.0), "alpine": dict(prom_scale=350.0,
          saddle_scale_m=2500.0), "mid": dict(prom_scale=150.0, saddle_scale_m=1400.0)}


@pytest.fixture(scope="module")
def feats():
    from helpers.classify_synth import make_peaks

    tables = []
    for k, (name, kw) in enumerate(STYLES.items()):
        p = peak_geometry(make_peaks(1500, rng=10 + k, **kw))
        d = sample_disks_in_polygon(shapely.box(0, -60_000, 60_000, 0), radius_m=10_000, rng=k)
        tables.append(feature_table(p, d, label=name, source=name))
    return concat_features(tables)


@settings(max_examples=30, deadline=None)
@given(counts=st.lists(st.integers(2, 130), min_size=2, max_size=6), seed=st.integers(0, 999))
def test_splits_disjoint_and_capped(counts, seed):
    labels = np.repeat([f"c{i}" for i in range(len(counts))], counts)
    g = np.random.default_rng(seed)
    x, y = g.uniform(0, 1e5, len(labels)), g.uniform(0, 1e5, len(labels))
    for tr, va in (random_split(labels, rng=seed), spatial_split(labels, x, y, buffer_m=5000.0, rng=seed)):
        assert not set(tr) & set(va)
        for c, n in zip(pd.unique(labels), counts):
            ntr, nva = np.sum(labels[tr] == c), np.sum(labels[va] == c)
            assert ntr <= 80 and 1 <= nva <= 20
    tr, va = spatial_split(labels, x, y, buffer_m=5000.0, rng=seed)
    for c in pd.unique(labels):  # no training centre within the buffer of a validation centre
        t, v = tr[labels[tr] == c], va[labels[va] == c]
        if len(t) and len(v):
            assert np.hypot(x[t, None] - x[None, v], y[t, None] - y[None, v]).min() > 5000.0


def test_small_classes():
    labels = ["a"] * 5 + ["b"] * 4 + ["c"]
    with pytest.raises(InputError, match="c: 1"):
        check_classes(labels)
    with pytest.warns(OrokitWarning, match="c: 1"):
        keep = check_classes(labels, small_classes="drop")
    assert keep.sum() == 9
    with pytest.raises(InputError, match="at least 2 regions"), pytest.warns(OrokitWarning, match="b: 1"):
        check_classes(["a"] * 5 + ["b"], small_classes="drop")


def test_evaluate_and_model_roundtrip(feats, tmp_path):
    ev = evaluate(feats, runs=4, feature_runs=2, rng=0)
    assert ev.mean_accuracy > 0.6  # 3 classes: chance is 1/3
    assert set(ev.per_feature) == set(feature_set_of(feats).groups())
    assert ev.confusion.sum() == sum(len(random_split(feats["label"], rng=0)[1]) for _ in range(4))
    sp = evaluate(feats, runs=3, split="spatial", feature_groups=False, rng=0)
    assert sp.params["buffer_m"] == 20_000.0
    # every run had training disks of every region far enough from its held-out strip
    assert np.isfinite(sp.accuracies).all() and min(sp.mean_train.values()) > 5
    assert sp.mean_accuracy > 0.6  # 3 well separated styles; chance is 1/3
    model = train_classifier(feats, rng=0)
    path = save_model(model, tmp_path / "m.skops", model_metadata(model, feats, evaluation={"x": 1}))
    m = load_model(path)
    assert m.classes == sorted(STYLES) and m.radius_m == 10_000.0
    pred = predict_regions(m, feats[feats["label"] == "alpine"])
    assert pred.label == "alpine" and sum(pred.votes.values()) == (feats["label"] == "alpine").sum()
    bad = feats.copy()
    bad.attrs = dict(feats.attrs, radius_m=5000.0)
    with pytest.raises(SchemaError, match="radius_m"):
        predict_regions(m, bad)


def test_model_from_other_version(feats, tmp_path):
    model = train_classifier(feats, n_estimators=5, rng=0)
    md = model_metadata(model, feats)
    path = save_model(model, tmp_path / "m.skops", dict(md, orokit_version="0.0.1"))
    with pytest.warns(OrokitWarning, match="0.0.1"):
        load_model(path)
    path = save_model(model, tmp_path / "m.skops", md)
    mp = metadata_path(path)
    side = json.loads(mp.read_text())
    mp.write_text(json.dumps(dict(side, format="orokit-region-classifier/1")))
    with pytest.raises(SchemaError, match="retrain"):
        load_model(path)
    mp.write_text(json.dumps(side))
    path.write_bytes(path.read_bytes() + b"x")
    with pytest.raises(InputError, match="sha256"):
        load_model(path)
    mp.unlink()
    with pytest.raises(InputError, match="metadata"):
        load_model(path)


def test_cli_features_train_classify(tmp_path):
    from helpers.classify_synth import make_peaks

    region = tmp_path / "region.gpkg"
    import geopandas as gpd

    gpd.GeoDataFrame(geometry=[shapely.box(0, -60_000, 60_000, 0)], crs="EPSG:32633").to_file(region)
    inputs = []
    for k, (name, kw) in enumerate(STYLES.items()):
        p = make_peaks(1200, rng=20 + k, **kw)
        g = gpd.GeoDataFrame(p, geometry=gpd.points_from_xy(p["x"], p["y"]), crs="EPSG:32633")
        g.to_parquet(tmp_path / f"{name}.parquet")
        inputs.append(str(tmp_path / f"{name}.parquet"))
    r = CliRunner()
    out = tmp_path / "f.parquet"
    res = r.invoke(cli, ["features", *inputs, "-o", str(out), "--radius", "10km", "--region", str(region),
                         "--no-progress"])
    assert res.exit_code == 0, res.output
    assert r.invoke(cli, ["features", *inputs, "-o", str(out), "--region", str(region)]).exit_code != 0  # exists
    assert r.invoke(cli, ["features", inputs[0], "-o", str(tmp_path / "g.parquet"), "--radius", "10"]).exit_code == 2
    res = r.invoke(cli, ["train", str(out), "-o", str(tmp_path / "m.skops"), "--runs", "3", "--feature-runs", "1",
                         "--json", "--no-progress", "--report", str(tmp_path / "rep")])
    assert res.exit_code == 0, res.output
    js = json.loads(res.output[res.output.index("{"):])
    assert {"mean_accuracy", "median_accuracy", "per_class", "per_feature"} <= set(js)
    assert (tmp_path / "rep" / "tables" / "table2.md").exists()
    res = r.invoke(cli, ["classify", str(tmp_path / "m.skops"), inputs[1], "--region", str(region), "--json"])
    assert res.exit_code == 0, res.output
    js = json.loads(res.output[res.output.index("{"):])
    assert js["label"] == "alpine" and abs(sum(js["probabilities"].values()) - 1) < 1e-6


@settings(max_examples=40, deadline=None)
@given(counts=st.lists(st.integers(1, 60), min_size=1, max_size=4), sources=st.integers(1, 3),
       block_km=st.floats(2.0, 30.0), buffer_km=st.floats(0.0, 25.0), seed=st.integers(0, 999))
def test_block_folds_buffer_and_cover(counts, sources, block_km, buffer_km, seed):
    from orokit.classify.train import block_folds

    labels = np.repeat([f"c{i}" for i in range(len(counts))], counts)
    g = np.random.default_rng(seed)
    groups = np.array([f"{lab}|s{g.integers(sources)}" for lab in labels], dtype=object)
    x, y = g.uniform(0, 6e4, len(labels)), g.uniform(-6e4, 0, len(labels))
    folds = block_folds(labels, x, y, groups=groups, block_m=block_km * 1e3, buffer_m=buffer_km * 1e3,
                        max_train=None, rng=seed)
    tested = np.concatenate([va for _, va in folds])
    assert sorted(tested.tolist()) == list(range(len(labels)))  # every disk held out exactly once
    for tr, va in folds:
        assert not set(tr) & set(va)
        for gname in set(groups[va]):  # no training centre of the same DEM within the buffer of a held-out one
            t, v = tr[groups[tr] == gname], va[groups[va] == gname]
            if len(t):
                assert np.hypot(x[t, None] - x[None, v], y[t, None] - y[None, v]).min() > buffer_km * 1e3
        # a disk that is far from every held-out disk of its DEM trains (nothing else is thrown away)
        rest = np.setdiff1d(np.arange(len(labels)), np.concatenate([tr, va]))
        for i in rest:
            v = va[groups[va] == groups[i]]
            assert np.hypot(x[i] - x[v], y[i] - y[v]).min() <= buffer_km * 1e3
    capped = block_folds(labels, x, y, groups=groups, block_m=block_km * 1e3, max_train=3, rng=seed)
    for tr, _ in capped:
        assert all(np.sum(labels[tr] == c) <= 3 for c in set(labels))


def test_block_split_tests_every_disk(feats):
    ev = evaluate(feats, runs=1, split="blocks", feature_groups=False, n_estimators=30, rng=0)
    assert ev.params["block_m"] == 10_000.0 and ev.params["buffer_m"] == 20_000.0
    n = len(feats)
    # each run tests every disk once, but for those whose region kept no training disk in their fold
    assert ev.confusion.sum() == n - ev.params["untested_disks_per_run"]
    assert ev.params["untested_disks_per_run"] < 0.2 * n
    assert np.isfinite(ev.accuracies).all() and ev.mean_accuracy > 0.6  # 3 styles; chance is 1/3
    sp = evaluate(feats, runs=2, split="spatial", feature_groups=False, n_estimators=30, rng=0)
    # the block split trains on more ground than the strip: that is its point
    assert sum(ev.mean_train.values()) > sum(sp.mean_train.values())


def test_cli_train_block_split(feats, tmp_path):
    path = tmp_path / "f.parquet"
    write_features(feats, path)
    res = CliRunner().invoke(cli, ["train", str(path), "-o", str(tmp_path / "m.skops"), "--runs", "1",
                                   "--feature-runs", "0", "--split", "blocks", "--block", "0.5", "--trees", "20",
                                   "--json", "--no-progress", "--seed", "0"])
    assert res.exit_code == 0, res.output
    js = json.loads(res.output[res.output.index("{"):])
    assert js["split"] == "blocks" and js["mean_accuracy"] > 0.6
    md = json.loads(metadata_path(tmp_path / "m.skops").read_text())
    assert md["evaluation"]["blocks"]["params"]["block_m"] == 5_000.0
