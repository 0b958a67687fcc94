"""Synthesis inputs are checked before anything is computed (issue 15)."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from orokit.cli.main import cli
from orokit.errors import InputError
from orokit.synthesis.tree import synthesize_divide_tree


@pytest.fixture()
def type_file(tmp_path, small_type):
    return small_type.save(tmp_path / "t.json")


def _run(tmp_path, type_file, *args):
    return CliRunner().invoke(cli, ["synthesize-tree", "--type", str(type_file), "--no-progress",
                                    "-o", str(tmp_path / "out"), *args])


def test_fixed_peak_with_nan_elevation_is_refused_before_writing(tmp_path, type_file):
    fixed = tmp_path / "fixed.csv"
    pd.DataFrame({"x": [3000.0, 6000.0], "y": [3000.0, 7000.0], "elevation": [2000.0, np.nan]}).to_csv(fixed,
                                                                                                     index=False)
    res = _run(tmp_path, type_file, "--size", "15km", "--peaks", str(fixed), "--seed", "1")
    assert res.exit_code == 1, res.output
    assert f"{fixed}: 1 fixed peak(s) have no valid elevation" in res.output and "row(s) 2" in res.output
    assert "Traceback" not in res.output and not (tmp_path / "out").exists()


def test_duplicate_fixed_peaks_are_refused(tmp_path, type_file):
    fixed = tmp_path / "fixed.csv"
    pd.DataFrame({"x": [3000.0, 6000.0, 3000.0], "y": [3000.0, 7000.0, 3000.0],
                  "elevation": [2000.0, 1800.0, 1500.0]}).to_csv(fixed, index=False)
    res = _run(tmp_path, type_file, "--size", "15km", "--peaks", str(fixed), "--seed", "1")
    assert res.exit_code == 1, res.output
    assert "data rows 1 and 3 share the position (3000, 3000)" in res.output
    assert not (tmp_path / "out").exists()


def test_library_refuses_nan_and_duplicates(small_type):
    with pytest.raises(InputError, match="no valid x"):
        synthesize_divide_tree(small_type, size_m=15_000, fixed_peaks=np.array([[np.nan, 10.0, 500.0]]), rng=0)
    with pytest.raises(InputError, match="share the position"):
        synthesize_divide_tree(small_type, size_m=15_000, fixed_peaks=np.array([[10.0, 10.0, 500.0]] * 2), rng=0)


@pytest.mark.parametrize("size", ["1m", "10m", "200m"])
def test_tiny_domains_return_at_once(tmp_path, type_file, size):
    """No hang: a domain without room for peaks is an error before any allocation or filtering.

    A subprocess with a generous timeout (the bug ran > 10 minutes); not a timing assertion."""
    proc = subprocess.run([sys.executable, "-m", "orokit.cli.main", "synthesize-tree", "--type", str(type_file),
                           "--size", size, "--no-progress", "-o", str(tmp_path / "out")],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 1, proc.stderr
    assert "too few for a Divide Tree" in proc.stderr and "Traceback" not in proc.stderr


def test_tiny_domain_with_explicit_peak_count_completes(small_type):
    tree = synthesize_divide_tree(small_type, size_m=50.0, n_peaks=5, rng=0)
    tree.validate()
    assert tree.n_peaks == 5
