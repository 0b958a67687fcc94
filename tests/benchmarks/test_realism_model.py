"""benchmarks/realism.py without the region model (a build product, not tracked): a clear stop, no silent run."""
from __future__ import annotations

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
