"""The in-memory ``orokit analyze`` path reaches its memory peak (the engine) without pandas.

pandas (with pyarrow) is ~70 MB resident; it is imported only when the tables are
built, after the engine's label array is freed (issue 13: peak RSS).
"""
from __future__ import annotations

import subprocess
import sys

CODE = """
import sys
import numpy as np
import orokit.cli.analyze, orokit.analysis, orokit.io.dem, orokit.io.analysis_io  # what the CLI imports first
from orokit.analysis import load_kernels
from orokit.topology import engine
load_kernels()  # what `orokit analyze` runs while GDAL reads
z = np.random.default_rng(0).random((40, 50))
core = engine.orometry(z, min_prominence_m=0.1)
assert core.n_kept > 0
print(sorted(m for m in ("pandas", "geopandas", "shapely", "pyogrio") if m in sys.modules))
"""


def test_engine_runs_without_pandas_imported():
    out = subprocess.run([sys.executable, "-c", CODE], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout + out.stderr
