"""The stage progress bar: on stderr only, one step per stage, silent with --no-progress."""
from __future__ import annotations

import numpy as np
import orokit
from click.testing import CliRunner

from orokit.cli.main import cli
from orokit.cli.progress import StageProgress
from orokit.io.analysis_io import write_analysis


def test_stage_progress_counts_and_writes_to_stderr(capsys):
    with StageProgress("work", ["a", "b", "c"]) as bar:
        bar.advance()
        bar.advance()
        bar.advance()
        bar.advance()  # past the end: stays at the last stage
    assert bar.done == 3
    cap = capsys.readouterr()
    assert cap.out == ""
    assert "work" in cap.err and "3/3" in cap.err


def test_stage_progress_disabled_prints_nothing(capsys):
    with StageProgress("work", ["a"], enabled=False) as bar:
        bar.advance()
    assert capsys.readouterr() == ("", "")


def test_compare_progress_on_stderr_and_off_with_no_progress(make_dem, tmp_path):
    z = np.random.default_rng(3).normal(size=(40, 50)).cumsum(0).cumsum(1)
    r = orokit.analyze(make_dem(z, res=0.0005, crs="EPSG:4326"), min_prominence_m=3, isolation=False)
    write_analysis(r, tmp_path / "a")
    on = CliRunner().invoke(cli, ["compare", str(tmp_path / "a"), str(tmp_path / "a"), "--progress"])
    assert on.exit_code == 0, on.output
    assert "compare" in on.stderr and "3/3" in on.stderr
    assert "3/3" not in on.stdout and "location precision / recall" in on.stdout
    off = CliRunner().invoke(cli, ["compare", str(tmp_path / "a"), str(tmp_path / "a"), "--no-progress"])
    assert off.exit_code == 0, off.output
    assert off.stderr == "" and off.stdout == on.stdout


def test_quiet_turns_the_progress_bars_off(make_dem, tmp_path):
    """``orokit -q`` prints only errors: no progress bars (before: compare's stage bar and the chunked
    analyze's dask bars were printed under -q)."""
    z = np.random.default_rng(3).normal(size=(40, 50)).cumsum(0).cumsum(1)
    r = orokit.analyze(make_dem(z, res=0.0005, crs="EPSG:4326"), min_prominence_m=3, isolation=False)
    write_analysis(r, tmp_path / "a")
    quiet = CliRunner().invoke(cli, ["-q", "compare", str(tmp_path / "a"), str(tmp_path / "a"), "--progress"])
    assert quiet.exit_code == 0, quiet.output
    assert quiet.stderr == "" and "location precision / recall" in quiet.stdout
    tif = tmp_path / "dem.tif"
    make_dem(z.astype("float32")).rio.to_raster(tif)
    run = CliRunner().invoke(cli, ["-q", "analyze", str(tif), "--chunks", "16", "-o", str(tmp_path / "b")])
    assert run.exit_code == 0, run.output
    assert run.stderr == "" and run.stdout == ""
