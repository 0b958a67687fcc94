"""benchmarks/rss_phases.py: the phases of an ``orokit`` process and their resident memory."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "rss_phases.py"


@pytest.mark.skipif(not Path("/proc/self/smaps").exists(), reason="Linux /proc")
def test_phases_of_a_small_analysis(tmp_path):
    import numpy as np
    import rasterio
    from rasterio.transform import Affine

    grid = np.random.default_rng(5).integers(0, 90, (60, 70)).astype(np.float32)
    dem = tmp_path / "dem.tif"
    with rasterio.open(dem, "w", driver="GTiff", width=70, height=60, count=1, dtype="float32", crs="EPSG:32633",
                       transform=Affine(30, 0, 500000, 0, -30, 4000000)) as ds:
        ds.write(grid, 1)
        ds.set_band_unit(1, "m")
    record = tmp_path / "rss.json"
    res = subprocess.run([sys.executable, str(SCRIPT), str(record), "-q", "analyze", str(dem), "-o",
                          str(tmp_path / "out"), "--no-progress", "--min-prominence", "5"],
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "out" / "peaks.csv").exists()
    phases = json.loads(record.read_text())["phases"]
    # a small raster's engine may pass between two samples: the command's own frame is always seen
    assert "analyze:analyze" in phases and "main:main" in phases
    for high in phases.values():
        assert 0 < high["RssAnon"] + high["RssFile"] <= high["VmRSS"] + 1
    assert res.stderr.splitlines()[0].startswith("peak RSS ")


@pytest.mark.skipif(not Path("/proc/self/smaps").exists(), reason="Linux /proc")
def test_libraries_ladder():
    import os

    # a user's own ARROW_DEFAULT_MEMORY_POOL stays (apply_process_settings): the ladder is measured without one
    env = {k: v for k, v in os.environ.items() if k != "ARROW_DEFAULT_MEMORY_POOL"}
    res = subprocess.run([sys.executable, str(SCRIPT), "--libraries"], capture_output=True, text=True, timeout=300,
                         env=env)
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines()
    assert lines[0] == "ARROW_DEFAULT_MEMORY_POOL=system" and lines[-1].startswith("+ geopandas")
    rss = [int(line.split("MiB")[0].split()[-1]) for line in lines[1:]]
    assert rss[-1] > rss[0] > 0
