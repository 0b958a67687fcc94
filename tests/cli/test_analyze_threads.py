"""`orokit analyze` in memory writes the same files with 1, 2 and 4 numba threads (the engine's row stripes)
and pinned to one core (every thread of the process: reader, writers)."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import rasterio
from rasterio.transform import Affine

FILES = ("peaks.csv", "peaks.parquet", "saddles.parquet")


def _dem(path: Path) -> Path:
    rng = np.random.default_rng(17)
    z = rng.integers(0, 60, (600, 90)).astype(np.float32)  # ties everywhere; 600 rows: stripes at 2 and 4 threads
    z[rng.random(z.shape) < 0.03] = np.nan
    with rasterio.open(path, "w", driver="GTiff", width=90, height=600, count=1, dtype="float32", crs="EPSG:32633",
                       transform=Affine(30, 0, 500000, 0, -30, 4000000), nodata=np.nan, tiled=True, blockxsize=16,
                       blockysize=16) as ds:
        ds.write(z, 1)
        ds.set_band_unit(1, "m")
    return path


def _run(dem: Path, out: Path, threads: int, pin: bool = False) -> dict[str, bytes]:
    env = dict(os.environ, NUMBA_NUM_THREADS=str(threads))
    cmd = [sys.executable, "-m", "orokit.cli.main", "-q", "analyze", str(dem), "-o", str(out), "--no-progress",
           "--min-prominence", "5"]
    if pin:
        cmd = [shutil.which("taskset") or "taskset", "-c", "0", *cmd]
    subprocess.run(cmd, check=True, env=env, capture_output=True)
    return {name: (out / name).read_bytes() for name in FILES}


def test_in_memory_files_do_not_depend_on_threads(tmp_path):
    dem = _dem(tmp_path / "dem.tif")
    one = _run(dem, tmp_path / "t1", 1)
    assert one["peaks.csv"].count(b"\n") > 100
    for threads in (2, 4):
        assert _run(dem, tmp_path / f"t{threads}", threads) == one, threads
    if sys.platform.startswith("linux") and shutil.which("taskset"):
        assert _run(dem, tmp_path / "pinned", 2, pin=True) == one
    else:
        pytest.skip("taskset (pin to one core) is Linux-only")
