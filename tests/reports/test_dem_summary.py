"""Per-dataset summary: statistics, hillshade, files, CLI."""
from __future__ import annotations

import json

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from click.testing import CliRunner  # noqa: E402

from orokit.cli.main import cli  # noqa: E402
from orokit.raster.shade import hillshade  # noqa: E402
from orokit.reports.dem_summary import (  # noqa: E402
    plot_hillshade,
    render_index,
    summarize_dem,
    write_dem_summary,
)


def test_summarize(make_dem):
    z = np.array([[0.0, 10.0], [np.nan, 30.0]])
    s = summarize_dem(make_dem(z, res=25.0))
    assert (s["rows"], s["cols"]) == (2, 2) and s["crs"] == "EPSG:32633"
    assert s["min_m"] == 0 and s["max_m"] == 30 and s["valid_fraction"] == 0.75
    assert s["zero_fraction"] == pytest.approx(1 / 3) and s["extent_x_km"] == pytest.approx(0.05)
    geo = summarize_dem(make_dem(np.ones((3, 3)), res=1 / 1200, crs="EPSG:4326", origin=(10, 60)))
    assert geo["cell_size_x_m"] == pytest.approx(geo["cell_size_y_m"] * 0.5, rel=0.01)


def test_hillshade_lit_and_shadowed_slopes(make_dem):
    x = np.arange(20, dtype=float)
    flat = hillshade(make_dem(np.zeros((5, 5))))
    np.testing.assert_allclose(flat, np.sin(np.radians(45)))
    # surface rising to the east faces west: lit by a western light, dark under an eastern one
    ramp = make_dem(np.tile(x * 30.0, (5, 1)), res=30.0)  # 45 degree slope
    assert hillshade(ramp, azimuth_deg=270, altitude_deg=45).mean() == pytest.approx(1.0)
    assert hillshade(ramp, azimuth_deg=90, altitude_deg=45).mean() == pytest.approx(0.0, abs=1e-12)
    # same slope in a geographic grid with narrower cells looks steeper (uses metres, not degrees)
    geo = make_dem(np.tile(x, (5, 1)), res=1 / 1200, crs="EPSG:4326", origin=(0, 60))
    utm = make_dem(np.tile(x, (5, 1)), res=92.6)
    assert hillshade(geo, azimuth_deg=90).mean() < hillshade(utm, azimuth_deg=90).mean()


def test_plot_returns_axes(make_dem):
    fig, ax = plt.subplots()
    try:
        assert plot_hillshade(ax, make_dem(np.random.default_rng(0).random((30, 40)) * 100), title="t") is ax
        assert ax.get_title() == "t" and ax.get_xlabel().startswith("x (km)")
    finally:
        plt.close(fig)


def test_write_summary_and_index(make_dem, tmp_path):
    dem = make_dem(np.random.default_rng(1).random((60, 50)) * 1000)
    dem.attrs.update(dataset="demo", title="Demo")
    paths = write_dem_summary(dem, tmp_path / "demo")
    assert paths["png"].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and paths["png"].stat().st_size < 200_000
    s = json.loads(paths["json"].read_text())
    assert s["dataset"] == "demo" and "![hillshade](hillshade.png)" in paths["md"].read_text()
    idx = render_index([paths["json"]], tmp_path / "README.md")
    assert "[demo](demo/summary.md)" in idx and "| Demo |" in idx


@pytest.mark.realdata
def test_cli_report_dataset(real_data, tmp_path):
    real_data("gobi")
    out = tmp_path / "gobi"
    runner = CliRunner()
    res = runner.invoke(cli, ["report-dataset", "gobi", "-o", str(out)])
    assert res.exit_code == 0, res.output
    md = (out / "summary.md").read_text()
    assert "local metric grid" in md and "92.61 m" in md and "sha256" in md
    assert (out / "hillshade.png").stat().st_size < 150_000
    res = runner.invoke(cli, ["report-dataset", "gobi", "-o", str(out)])
    assert res.exit_code == 2 and "--overwrite" in res.output  # a usage error, as in every command
    assert runner.invoke(cli, ["report-dataset", "gobi", "-o", str(out), "--overwrite"]).exit_code == 0
    res = runner.invoke(cli, ["report-index", str(out / "summary.json"), "-o", str(tmp_path / "README.md")])
    assert res.exit_code == 0 and "[gobi](gobi/summary.md)" in (tmp_path / "README.md").read_text()
