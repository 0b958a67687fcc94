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
    # the model carries the calibration fitted on the spatial hold-out; the plain output names the unknown disks
    cal = load_model(tmp_path / "m.skops").calibration
    assert cal.temperature != 1.0 and js["unknown_threshold"] == pytest.approx(cal.terrain_threshold)
    assert js["unknown_disks"] == sum(d["answer"] == "unknown" for d in js["disks"])
    res = r.invoke(cli, ["classify", str(tmp_path / "m.skops"), inputs[1], "--region", str(region)])
    assert res.exit_code == 0 and "alpine" in res.output and f"{js['unknown_disks']} of them unknown" in res.output
    res = r.invoke(cli, ["classify", str(tmp_path / "m.skops"), inputs[1], "--region", str(region), "--threshold", "2",
                         "--disk-threshold", "2", "--json"])
    js = json.loads(res.output[res.output.index("{"):])
    assert js["label"] == "unknown" and js["best"] == "alpine" and js["unknown_disks"] == js["n_disks"]


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


def test_calibrated_predictions_and_unknown_answers(feats, tmp_path):
    from orokit.classify.calibration import Calibration, softmax, temper
    from orokit.classify.predict import UNKNOWN

    sp = evaluate(feats, runs=3, split="spatial", feature_groups=False, rng=0)
    # every tested disk's held-out probabilities are kept, rows sum to 1, true columns match the confusion rows
    assert len(sp.heldout_true) == sp.confusion.sum() and sp.heldout_proba.shape == (sp.confusion.sum(), 3)
    np.testing.assert_allclose(sp.heldout_proba.sum(axis=1), 1.0)
    np.testing.assert_array_equal(np.bincount(sp.heldout_true, minlength=3), sp.confusion.sum(axis=1))
    check = sp.calibration_check()
    assert check["disks"]["raw"]["accuracy"] == pytest.approx(sp.mean_accuracy, abs=0.05)
    model = train_classifier(feats, rng=0)
    md = model_metadata(model, feats)
    alpine = feats[feats["label"] == "alpine"]
    plain = predict_regions(load_model(save_model(model, tmp_path / "a.skops", md)), alpine)
    cal = Calibration(temperature=0.5, terrain_temperature=3.0, disk_threshold=0.9, terrain_threshold=0.99)
    m = load_model(save_model(model, tmp_path / "b.skops", dict(md, calibration=cal.to_dict())))
    assert m.calibration == cal
    pred = predict_regions(m, alpine)
    q = temper(model.predict_proba(alpine[m.feature_names].to_numpy(float)), 0.5)
    np.testing.assert_allclose(pred.disks[[f"proba_{c}" for c in m.classes]].to_numpy(float), q)
    # one temperature for all classes: the best class of the terrain and of each disk are unchanged
    assert pred.best == plain.best == "alpine" and (pred.disks["predicted"] == plain.disks["predicted"]).all()
    np.testing.assert_allclose(list(pred.probabilities.values()), softmax(np.log(q).sum(axis=0) / 3.0))
    assert pred.label == (UNKNOWN if q[:, m.classes.index("alpine")].mean() < 0.99 else "alpine")
    assert (pred.disks["answer"] == UNKNOWN).sum() == (q.max(axis=1) < 0.9).sum() == pred.unknown_disks
    forced = predict_regions(m, alpine, threshold=0.0, disk_threshold=0.0)
    assert forced.label == "alpine" and forced.unknown_disks == 0
    # a model saved before calibration existed keeps its terrain threshold and its probabilities
    old = load_model(save_model(model, tmp_path / "c.skops", dict(md, unknown_threshold=0.42)))
    assert old.calibration == Calibration(terrain_threshold=0.42)


def test_open_set_never_trains_on_the_left_out_region(feats):
    from orokit.classify.train import evaluate_open_set
    from helpers.classify_synth import make_peaks

    # a fourth region drawn like "alpine": left out, it is taken for alpine (and alpine for it)
    p = peak_geometry(make_peaks(1500, rng=99, **STYLES["alpine"]))
    d = sample_disks_in_polygon(shapely.box(0, -60_000, 60_000, 0), radius_m=10_000, rng=9)
    four = concat_features([feats, feature_table(p, d, label="alpine-twin", source="alpine-twin")])
    res = evaluate_open_set(four, runs=1, n_estimators=30, rng=0)
    rows = {r["region"]: r for r in res.rows}
    assert set(rows) == {"alpine", "alpine-twin", "mid", "rolling"}
    assert all(r["answered_as"] != name for name, r in rows.items())
    assert rows["alpine-twin"]["answered_as"] == "alpine" and rows["alpine"]["answered_as"] == "alpine-twin"
    for r in res.rows:
        for k in ("unknown_disks", "unknown_terrain", "known_unknown_disks", "known_unknown_terrain"):
            assert 0.0 <= r[k] <= 1.0
        assert 0.0 <= r["auroc"] <= 1.0 and r["runs"] == 1
    # the twin is a known kind of ground: its disks are no more often unknown than chance would make a
    # known region's held-out disks (the threshold keeps 95 % of right answers)
    assert rows["alpine-twin"]["unknown_disks"] < 0.5
    with pytest.raises(InputError, match=">= 3 regions"):
        evaluate_open_set(feats[feats["label"] != "mid"], runs=1)


def test_calibration_page(feats, tmp_path):
    from orokit.classify.train import evaluate_open_set
    from orokit.reports.classification_calibration import calibration_files, write_calibration_page

    sp = evaluate(feats, runs=3, split="spatial", feature_groups=False, rng=0)
    op = evaluate_open_set(feats, runs=1, n_estimators=30, rng=0)
    path = write_calibration_page(sp, op, tmp_path, radius_m=10_000.0, command="test")
    files = calibration_files(10_000.0, tmp_path, open_set=True)
    assert path == files[0] and all(f.exists() for f in files)
    text = path.read_text()
    cal = sp.calibration()
    assert f"temperature **{cal.temperature:.3f}**" in text and "leave one region out" in text
    assert len(pd.read_csv(files[-1])) == 3  # one row per left-out region
    assert files[1].stat().st_size > 10_000  # the reliability figure
