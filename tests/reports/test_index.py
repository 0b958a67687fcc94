"""reports/README.md links every section that exists."""
from __future__ import annotations

import json

from click.testing import CliRunner

from orokit.cli.main import cli
from orokit.reports.index import render_sections, report_sections


def _page(path, title):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(f"# {title}\n\ntext\n")


def test_sections_in_pipeline_order_then_new_ones(tmp_path):
    _page(tmp_path / "roundtrip" / "README.md", "Round trip")
    _page(tmp_path / "roundtrip" / "relief" / "README.md", "Round trip with the real relief")
    _page(tmp_path / "analysis" / "README.md", "Exact analysis")
    _page(tmp_path / "zeta" / "README.md", "A new stage")
    (tmp_path / "benchmarks").mkdir()
    (tmp_path / "benchmarks" / "analyze.json").write_text("{}")
    (tmp_path / "benchmarks" / "notes.png").write_bytes(b"")  # not a result file: not listed
    (tmp_path / "datasets" / "gobi").mkdir(parents=True)     # the datasets table is the index itself
    links = [link for link, _ in report_sections(tmp_path)]
    assert links == ["analysis/README.md", "roundtrip/README.md", "roundtrip/relief/README.md",
                     "benchmarks/analyze.json", "zeta/README.md"]
    text = render_sections(tmp_path)
    assert "- [roundtrip/relief](roundtrip/relief/README.md): Round trip with the real relief" in text
    assert render_sections(tmp_path / "missing") == ""


def test_report_index_links_sections(tmp_path):
    reports = tmp_path / "reports"
    summary = reports / "datasets" / "gobi" / "summary.json"
    summary.parent.mkdir(parents=True)
    summary.write_text(json.dumps({"dataset": "gobi", "title": "Gobi", "rows": 2, "cols": 3, "cell_size_x_m": 92.6,
                                   "local_grid": True, "crs": None, "min_m": 1.0, "max_m": 2.0}))
    _page(reports / "synthesis" / "README.md", "Divide Tree synthesis")
    out = reports / "README.md"
    res = CliRunner().invoke(cli, ["report-index", str(summary), "-o", str(out)])
    assert res.exit_code == 0, res.output
    text = out.read_text()
    assert "[synthesis](synthesis/README.md): Divide Tree synthesis" in text
    assert "[gobi](datasets/gobi/summary.md)" in text
    assert text.index("## Sections") < text.index("## Datasets")
