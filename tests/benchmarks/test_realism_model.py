"""benchmarks/realism.py without the region model (a build product, not tracked): a clear stop, no silent run."""
from __future__ import annotations

import json

import pytest

import realism


def _no_run(*args, **kwargs):
    raise AssertionError("a region was run")


def test_missing_default_model_names_the_make_target(tmp_path, monkeypatch):
    monkeypatch.setattr(realism, "REGION_MODEL", tmp_path / "models" / "regions-10km.skops")
    monkeypatch.setattr(realism, "run_region", _no_run)
    with pytest.raises(SystemExit, match=r"not found: build it with `make region-model`.*--no-model"):
        realism.main(["--regions", "gobi", "--no-record"])


def test_missing_given_model_names_the_path(tmp_path, monkeypatch):
    monkeypatch.setattr(realism, "run_region", _no_run)
    with pytest.raises(SystemExit, match=r"other\.skops not found: check the path"):
        realism.main(["--regions", "gobi", "--no-record", "--model", str(tmp_path / "other.skops")])


def test_no_model_runs_without_reclassification(tmp_path, monkeypatch):
    monkeypatch.setattr(realism, "REGION_MODEL", tmp_path / "missing.skops")
    seen = {}

    def fake_run(name, **kw):
        seen[name] = kw["model"]
        raise KeyboardInterrupt  # stop after the first region: the model was not needed

    monkeypatch.setattr(realism, "run_region", fake_run)
    with pytest.raises(KeyboardInterrupt):
        realism.main(["--regions", "gobi", "--no-record", "--no-model"])
    assert seen == {"gobi": None}


def test_relief_twins_pass_the_real_relief_and_skip_the_render(tmp_path, monkeypatch):
    """--control-elevation like: every region's twin gets the real DEM as C_H, no render of the real tree, the
    run says so in its JSON, and --combine refuses to merge it with a run of free twins."""
    seen = {}

    def fake_run(name, **kw):
        seen[name] = (kw["relief"], kw["render_real"])
        return {"twin": {}}

    monkeypatch.setattr(realism, "run_region", fake_run)
    monkeypatch.setattr(realism, "_markdown", lambda results: "")
    monkeypatch.setattr(realism, "_drift_markdown", lambda results: "")
    monkeypatch.setattr(realism, "_ridges_markdown", lambda results: "")
    out = tmp_path / "relief.json"
    realism.main(["--regions", "gobi,norway", "--no-record", "--no-model", "--control-elevation", "like",
                  "--json", str(out)])
    assert seen == {"gobi": (True, False), "norway": (True, False)}
    assert json.loads(out.read_text())["control_elevation"] == "like"
    free = tmp_path / "free.json"
    realism.main(["--regions", "gobi", "--no-record", "--no-model", "--json", str(free)])
    assert seen["gobi"] == (False, True)
    assert json.loads(free.read_text())["control_elevation"] is None
    with pytest.raises(SystemExit, match="control_elevation"):
        realism.main(["--no-model", "--no-record", "--combine", str(out), str(free)])
