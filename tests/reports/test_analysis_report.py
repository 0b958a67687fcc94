"""orokit analysis-report on a real DEM: table row, reference agreement and figure."""
from __future__ import annotations

import pytest
from click.testing import CliRunner

from orokit.cli.main import cli


@pytest.mark.realdata
def test_analysis_report_on_a_real_dem(real_data, tmp_path):
    real_data("norway")  # make sure the DEM and its reference tree are available
    real_data("dems/norway.txt")
    runner = CliRunner()
    out = tmp_path / "norway"
    r = runner.invoke(cli, ["analyze", "norway", "-o", str(out), "--no-progress"])
    assert r.exit_code == 0, r.output
    report = tmp_path / "report" / "README.md"
    r = runner.invoke(cli, ["analysis-report", str(out), "-o", str(report)])
    assert r.exit_code == 0, r.output
    text = report.read_text()
    row = next(line for line in text.splitlines() if line.startswith("| norway"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[1] == "648x648" and int(cells[2]) > 100
    assert float(cells[7].rstrip("%")) >= 97.0  # reference peaks at or next to ours
    assert "time" not in row and (tmp_path / "report" / "timings.csv").read_text().startswith("dataset,seconds\nnorway,")
    assert (tmp_path / "report" / "figures" / "norway.png").stat().st_size > 10_000
    r = runner.invoke(cli, ["analysis-report", str(out), "-o", str(report)])
    assert r.exit_code != 0 and "overwrite" in r.output
