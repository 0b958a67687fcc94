"""Golden analysis tables of two small real DEMs (refactors must show any change).

``orokit analyze NAME --min-prominence EPS`` (as ``make report`` runs it) on

- ``gobi`` at 30 m: a 648 x 648 PNG in feet on a local metric grid (the paper's crops), and
- ``pysheds-dem`` at 5 m: a 359 x 367 GeoTIFF on a lon/lat grid (geodesic distances, voids;
  a low relief, hence the lower threshold),

and its ``peaks.parquet`` and ``saddles.parquet`` (all columns but the geometry) compared column by column with
``tests/golden/<name>_{peaks,saddles}.csv``: same columns in the same order, integer and
boolean columns equal, floats equal within ``RTOL`` (elevations and prominences are exact
graph quantities, so any change is a real change). The files are derived tables, never
the DEMs. After an intended change, rewrite them with ``pytest tests/golden --update-golden``
and review the diff.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from orokit.cli.main import cli

GOLDEN = Path(__file__).parent
#: relative tolerance of float columns (CSV round trip and summation order only)
RTOL = 1e-9
#: absolute tolerance of float columns (coordinates in degrees or metres, angles)
ATOL = 1e-9
#: dataset -> prominence threshold
CASES = {"gobi": "30", "pysheds-dem": "5"}  # metres

pytestmark = pytest.mark.realdata


def _analyse(name: str, eps: str, tmp_path: Path, real_data) -> dict[str, pd.DataFrame]:
    real_data(name)  # fetched into the cache (fails under CI=true when the data is missing)
    out = tmp_path / name
    res = CliRunner().invoke(cli, ["-q", "analyze", name, "-o", str(out), "--min-prominence", eps,
                                   "--no-progress"])
    assert res.exit_code == 0, res.output
    return {table: pd.DataFrame(pd.read_parquet(out / f"{table}.parquet").drop(columns="geometry")).reset_index()
            for table in ("peaks", "saddles")}


def _compare(name: str, table: str, got: pd.DataFrame, want: pd.DataFrame) -> None:
    where = f"{name}_{table}.csv"
    assert list(got.columns) == list(want.columns), f"{where}: columns changed"
    assert len(got) == len(want), f"{where}: {len(got)} rows instead of {len(want)}"
    for col in want.columns:
        a, b = got[col].to_numpy(), want[col].to_numpy()
        if want[col].dtype.kind == "f" or got[col].dtype.kind == "f":
            np.testing.assert_allclose(a.astype(float), b.astype(float), rtol=RTOL, atol=ATOL, equal_nan=True,
                                       err_msg=f"{where}: column {col!r}")
        else:
            mismatch = np.flatnonzero(a != b)
            assert mismatch.size == 0, (f"{where}: column {col!r} differs in {mismatch.size} rows, first at row "
                                        f"{mismatch[0]}: {a[mismatch[0]]!r} != {b[mismatch[0]]!r}")


@pytest.mark.parametrize("name", CASES)
def test_analysis_tables_match_golden(name, tmp_path, real_data, update_golden):
    tables = _analyse(name, CASES[name], tmp_path, real_data)
    for table, got in tables.items():
        path = GOLDEN / f"{name}_{table}.csv"
        if update_golden:
            got.to_csv(path, index=False, float_format="%.17g", lineterminator="\n")
            continue
        assert path.exists(), f"{path} missing: create it with `pytest tests/golden --update-golden`"
        want = pd.read_csv(path)
        # the CSV read-back of the fresh table, so both sides went through the same parser
        _compare(name, table, pd.read_csv(_to_csv(got, tmp_path / f"{table}.csv")), want)


def _to_csv(df: pd.DataFrame, path: Path) -> Path:
    df.to_csv(path, index=False, float_format="%.17g", lineterminator="\n")
    return path


def test_golden_tables_are_not_trivial():
    """The pinned tables hold what they claim (guards against an empty or truncated golden file)."""
    for name in CASES:
        peaks = pd.read_csv(GOLDEN / f"{name}_peaks.csv")
        saddles = pd.read_csv(GOLDEN / f"{name}_saddles.csv")
        assert len(peaks) > 20 and len(saddles) >= len(peaks) - 1
        assert (peaks["prominence"] >= float(CASES[name])).all()
        top = peaks.loc[peaks["elevation"].idxmax()]
        assert top["prominence"] == top["elevation"]  # the highest peak of a domain (paper convention)
