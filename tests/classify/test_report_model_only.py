"""`orokit report --model-only` (`make region-model`): the report's model without the report."""
from __future__ import annotations

import json

import numpy as np
from click.testing import CliRunner

from orokit.cli.main import cli


def test_model_only_gives_the_reports_model(tmp_path):
    from helpers.region_model import STYLES, style_dem
    from orokit.classify.model import load_model
    from orokit.io.model_io import read_feature_table

    inputs = []
    for k, name in enumerate(STYLES):
        path = tmp_path / f"{name}.tif"
        style_dem(name, size_km=30.0, rng=k).rio.to_raster(path)
        inputs.append(str(path))
    common = ["--radius", "3km", "--features", "orometry", "--runs", "3", "--min-peaks", "5", "--max-disks", "25",
              "--seed", "4", "--no-progress"]
    r = CliRunner()
    res = r.invoke(cli, ["report", *inputs, "-o", str(tmp_path / "rep"), "--model", str(tmp_path / "rep.skops"),
                         "--feature-runs", "0", *common])
    assert res.exit_code == 0, res.output
    res = r.invoke(cli, ["report", *inputs, "-o", str(tmp_path / "alone"), "--model", str(tmp_path / "alone.skops"),
                         "--model-only", *common])
    assert res.exit_code == 0, res.output
    assert "spatial hold-out" in res.output and "model ->" in res.output
    assert sorted(p.name for p in (tmp_path / "alone").rglob("*") if p.is_file()) == ["features_3km.parquet"]
    full, alone = load_model(tmp_path / "rep.skops"), load_model(tmp_path / "alone.skops")
    # the same disks, the same calibration, the same trees: the same answers
    feats = read_feature_table(tmp_path / "rep" / "features" / "features_3km.parquet")
    assert (tmp_path / "alone" / "features" / "features_3km.parquet").read_bytes() == \
        (tmp_path / "rep" / "features" / "features_3km.parquet").read_bytes()
    assert full.metadata["calibration"] == alone.metadata["calibration"]
    assert full.calibration.temperature != 1.0
    X = feats[full.feature_names].to_numpy(float)
    assert np.array_equal(full.predict_proba(X), alone.predict_proba(X))
    assert sorted(full.metadata["evaluation"]) == ["random", "spatial"]
    assert sorted(alone.metadata["evaluation"]) == ["spatial"]
    assert {k: v for k, v in full.metadata.items() if k != "evaluation"} == \
        {k: v for k, v in alone.metadata.items() if k != "evaluation"}
    # an existing model is kept without --overwrite; --model-only needs --model
    res = r.invoke(cli, ["report", *inputs, "-o", str(tmp_path / "alone"), "--model", str(tmp_path / "alone.skops"),
                         "--model-only", *common])
    assert res.exit_code == 2 and "--overwrite" in res.output
    res = r.invoke(cli, ["report", *inputs, "-o", str(tmp_path / "x"), "--model-only", *common])
    assert res.exit_code == 2 and "--model-only needs --model" in res.output
    assert json.loads((tmp_path / "alone.skops.json").read_text())["training_features"] == "features_3km.parquet"
