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


WRITING = """
import atexit, sys
import numpy as np
import rasterio
from rasterio.transform import from_origin

z = (np.random.default_rng(0).random((60, 70)) * 100).astype("float32")
with rasterio.open(sys.argv[1], "w", driver="GTiff", height=60, width=70, count=1, dtype="float32",
                   crs="EPSG:32633", transform=from_origin(500000, 4000000, 30, 30)) as dst:
    dst.write(z, 1)
atexit.register(lambda: print(sorted(m for m in ("geopandas", "shapely", "pyogrio", "scipy.linalg") if m in sys.modules)))
from orokit.cli.main import main

sys.argv = ["orokit", "-q", "analyze", sys.argv[1], "-o", sys.argv[2], "--no-progress"]
main()
"""


def test_analyze_writes_its_files_without_geopandas_shapely_or_pyogrio(tmp_path):
    """The whole ``orokit analyze`` process (the console script) writes the CSV, the GeoParquet
    tables and the GeoPackage through pyarrow and rasterio's GDAL: pyogrio's GDAL, shapely and
    geopandas (~34 MiB resident) are never loaded (issue 13). pandas still is (the tables are frames).
    Nor is scipy.linalg: numba's BLAS probe is skipped though its target starts before (the read waits for it)."""
    out = tmp_path / "out"
    res = subprocess.run([sys.executable, "-c", WRITING, str(tmp_path / "dem.tif"), str(out)],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.strip().splitlines()[-1] == "[]", res.stdout + res.stderr
    assert (out / "analysis.json").is_file() and (out / "dividetree.gpkg").is_file()


TARGET = """
import sys
from numba.core.runtime.nrt import rtsys
from orokit.analysis import load_kernels, start_numba_target
from orokit.cli.analyze import _numba_without_blas_probe

start_numba_target()
print(rtsys._init, "numba.np.arraymath" in sys.modules, "scipy.linalg" in sys.modules)
_numba_without_blas_probe()
load_kernels(isolation=False)  # the first kernel loads the target's implementations
print(rtsys._init, "numba.np.arraymath" in sys.modules, "scipy.linalg" in sys.modules)
"""


def test_numba_target_starts_without_its_implementations():
    """What the read waits for (LLVM's code generator and numba's runtime: LLVM's pages) does not load numba's
    implementations (~0.2 CPU s of Python, no LLVM page): those load with the first kernel, beside the read
    (issue 13: the 2-core run's serial start), after the BLAS probe is skipped."""
    out = subprocess.run([sys.executable, "-c", TARGET], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["True", "False", "False", "True", "True", "False"], out.stdout + out.stderr


SEARCH = """
import sys
import threading
import numpy as np
import rasterio
from rasterio.transform import from_origin

import orokit.metrics.isolation as isolation

z = (np.random.default_rng(1).random((60, 70)) * 100).astype("float32")
with rasterio.open(sys.argv[1], "w", driver="GTiff", height=60, width=70, count=1, dtype="float32",
                   crs="EPSG:32633", transform=from_origin(500000, 4000000, 30, 30)) as dst:
    dst.write(z, 1)
seen = []
search = isolation.nearest_higher


def recorded(*args, **kw):
    found = search(*args, **kw)
    # at the search's end: the libraries loaded, or a thread loading them
    seen.append(sorted(m for m in ("pandas", "pyarrow") if m in sys.modules)
                + [t.name for t in threading.enumerate() if t.name == "orokit-imports"])
    return found


isolation.nearest_higher = recorded
from orokit.analysis import analyze
from orokit.io.dem import read_dem_array

result = analyze(read_dem_array(sys.argv[1]), min_prominence_m=5, isolation=True, blocks=True, geometry=False,
                 release_dem=True)
assert len(result.peaks) > 0
print(seen)
"""


def test_isolation_search_runs_before_pandas_and_pyarrow_load(tmp_path):
    """With isolation, ``orokit analyze`` (``analyze(..., release_dem=True)``) holds the raster until the
    search is done; pandas and pyarrow (~68 MiB resident) load after it lets the raster go (beside the
    search they set the process's peak at 15.1 M cells, session 15)."""
    out = subprocess.run([sys.executable, "-c", SEARCH, str(tmp_path / "dem.tif")], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().splitlines()[-1] == "[[]]", out.stdout + out.stderr
