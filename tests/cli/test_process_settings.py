"""Process-wide settings of ``orokit analyze`` (two malloc arenas, Arrow's memory pool, LLVM's pages
dropped) belong to the ``orokit`` program's own process (the console script ``main()``), never to the
process of a caller that runs the click command (a ``CliRunner`` test, a script)."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import rasterio
from click.testing import CliRunner
from rasterio.transform import Affine

import orokit.tiling.memory as memory
from orokit.cli.main import SWITCH_INTERVAL_S, WRITING_SWITCH_INTERVAL_S, cli


def _dem(path: Path) -> Path:
    z = np.random.default_rng(3).integers(0, 80, (60, 50)).astype(np.float32)
    with rasterio.open(path, "w", driver="GTiff", width=50, height=60, count=1, dtype="float32", crs="EPSG:32633",
                       transform=Affine(30, 0, 500000, 0, -30, 4000000), nodata=np.nan) as ds:
        ds.write(z, 1)
        ds.set_band_unit(1, "m")
    return path


def test_cli_runner_call_leaves_the_callers_process_alone(tmp_path, monkeypatch):
    calls: list[str] = []
    monkeypatch.setattr(memory, "limit_malloc_arenas", lambda n: calls.append(f"arenas {n}") or True)
    monkeypatch.setattr(memory, "fix_mmap_threshold", lambda n: calls.append(f"mmap {n}") or True)
    monkeypatch.setattr(memory, "release_library_pages", lambda name: calls.append(f"drop {name}") or 0)
    monkeypatch.delenv("ARROW_DEFAULT_MEMORY_POOL", raising=False)
    interval = sys.getswitchinterval()
    res = CliRunner().invoke(cli, ["-q", "analyze", str(_dem(tmp_path / "dem.tif")), "-o", str(tmp_path / "out"),
                                   "--no-progress", "--min-prominence", "5"])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "out" / "peaks.csv").exists()
    assert calls == []
    assert "ARROW_DEFAULT_MEMORY_POOL" not in os.environ
    assert sys.getswitchinterval() == interval


#: the console script's process, with the settings' functions recorded (they would act the same)
SCRIPT = """
import os, sys
import orokit.tiling.memory as memory
calls = []
memory.limit_malloc_arenas = lambda n: calls.append(f"arenas {n}") or True
memory.fix_mmap_threshold = lambda n: calls.append(f"mmap {n}") or True
memory.release_library_pages = lambda name: calls.append(f"drop {name}") or 0
import orokit.io.dem as dem
_read = dem.read_dem_array
read_interval = []
dem.read_dem_array = lambda *a, **k: (read_interval.append(sys.getswitchinterval()), calls.append("read")) and _read(*a, **k)
import atexit
atexit.register(lambda: print((read_interval or [None])[0], sys.getswitchinterval(), calls,
                              os.environ.get("ARROW_DEFAULT_MEMORY_POOL")))
from orokit.cli.main import main
sys.argv = ["orokit", *sys.argv[1:]]
main()
"""


def _console(*args: str, env: dict | None = None, script: str = SCRIPT) -> str:
    base = {k: v for k, v in os.environ.items()
            if k not in ("ARROW_DEFAULT_MEMORY_POOL", "GDAL_CACHEMAX", "OPENBLAS_NUM_THREADS")}
    res = subprocess.run([sys.executable, "-c", script, *args], capture_output=True, text=True, timeout=300,
                         env={**base, **(env or {})})
    assert res.returncode == 0, res.stderr
    return res.stdout.splitlines()[-1]


#: what the console script's ``analyze`` (in memory) calls, in order, the kernel loader's drop of LLVM's pages aside
ANALYZE_CALLS = ["arenas 2", "mmap 1048576", "drop ", "drop ", "read", "drop ", "drop "]


def _analyze_calls(line: str, after_loader: int = 2) -> tuple[list[str], str]:
    """The recorded calls without the loader's ``drop libllvmlite`` (its thread runs beside the read: it comes
    once, before the main thread's last ``after_loader`` drops: its drop after joining the loader and before
    writing; a large raster's engine starts beside the loader, only the latter), and Arrow's pool."""
    import ast

    head, _, pool = line.rpartition("] ")
    read_interval, end_interval, head = head.split(" ", 2)
    # the GIL's switch interval: short through the read and the engine, Python's default for the writing
    assert (float(read_interval), float(end_interval)) == (SWITCH_INTERVAL_S, WRITING_SWITCH_INTERVAL_S)
    calls = ast.literal_eval(head + "]")
    loader = [i for i, c in enumerate(calls) if c == "drop libllvmlite"]
    assert len(loader) == 1 and loader[0] < len(calls) - after_loader, calls
    return [c for c in calls if c != "drop libllvmlite"], pool


def test_console_script_applies_them_to_analyze(tmp_path):
    dem = str(_dem(tmp_path / "dem.tif"))
    args = ["-q", "analyze", dem, "--no-progress", "--min-prominence", "5", "-o"]
    # the pages of files are dropped by the loader before numba's target starts, by the main thread once it
    # started (LLVM's, the imports') and before the raster is read (together they were the process's peak at
    # 15.1 M cells, session 14), after the read and the kernels' loading, and before writing
    assert _analyze_calls(_console(*args, str(tmp_path / "a"))) == (ANALYZE_CALLS, "system")
    # chunked: glibc's own 32 MB ceiling once the chunked engine is chosen (per-batch arrays reused from the heap)
    chunked = _console(*args, str(tmp_path / "c"), "--chunks", "32")
    assert "'mmap 1048576', 'mmap 33554432'" in chunked and "'read'" not in chunked, chunked
    # a user's choice of Arrow's pool stays
    assert _console(*args, str(tmp_path / "b"), env={"ARROW_DEFAULT_MEMORY_POOL": "jemalloc"}).endswith("jemalloc")


@pytest.mark.realdata
def test_a_dataset_name_read_whole_keeps_the_in_memory_mmap_threshold(real_data, tmp_path):
    """A manifest DEM analysed without --chunks is read whole (through xarray): the 1 MB threshold of an
    in-memory run stays (before: 30de9df's chunked 32 MB was set on that path too)."""
    real_data("gobi")
    line = _console("-q", "analyze", "gobi", "--no-progress", "--min-prominence", "100", "--no-isolation", "-o",
                    str(tmp_path / "a"))
    assert "'mmap 1048576'" in line and "33554432" not in line, line


@pytest.mark.realdata
def test_a_dataset_name_too_large_for_memory_is_analysed_in_chunks(real_data, tmp_path, monkeypatch):
    """The automatic chunk plan holds for a manifest DEM given by name, as for its file (before: read whole
    whatever the free memory)."""
    import orokit.analysis

    real_data("gobi")
    monkeypatch.setattr(orokit.analysis, "available_memory", lambda: 1 << 20)
    res = CliRunner().invoke(cli, ["analyze", "gobi", "--no-progress", "--min-prominence", "100", "--no-isolation",
                                   "-o", str(tmp_path / "a")])
    assert res.exit_code == 0, res.output
    assert "is too large for memory: analysing in 2048 x 2048 chunks" in res.stderr, res.stderr


#: the console script's process, printing the size of GDAL's block cache at its end (rasterio asks GDAL)
GDAL_CACHE = SCRIPT.replace("""print((read_interval or [None])[0], sys.getswitchinterval(), calls,
                              os.environ.get("ARROW_DEFAULT_MEMORY_POOL"))""",
                            'print(__import__("rasterio.env").env.get_gdal_config("GDAL_CACHEMAX"))')


def test_console_script_bounds_gdals_cache_for_analyze(tmp_path):
    """``orokit analyze`` bounds GDAL's block cache for its whole process: 32 MB chunked, 4 MB in memory (a
    whole read reads no block twice); a user's ``GDAL_CACHEMAX`` wins; another command keeps GDAL's
    default (the library never changes it: tests/io/test_read_dem_array.py)."""
    assert GDAL_CACHE != SCRIPT
    dem = str(_dem(tmp_path / "dem.tif"))
    args = ["-q", "analyze", dem, "--no-progress", "--min-prominence", "5", "-o"]
    assert _console(*args, str(tmp_path / "a"), script=GDAL_CACHE) == str(4 * 2**20)
    assert _console(*args, str(tmp_path / "b"), "--chunks", "32", script=GDAL_CACHE) == str(32 * 2**20)
    assert _console(*args, str(tmp_path / "c"), env={"GDAL_CACHEMAX": "123456789"}, script=GDAL_CACHE) == "123456789"
    assert _console("data", "list", script=GDAL_CACHE) != str(32 * 2**20)


#: the console script's process (numpy not imported before it starts), printing at its end the
#: ``OPENBLAS_NUM_THREADS`` of its environment and the threads of numpy's OpenBLAS (threadpoolctl, a
#: dependency of scikit-learn)
BLAS = """
import atexit, os, sys
def report():
    from threadpoolctl import threadpool_info
    print(os.environ.get("OPENBLAS_NUM_THREADS"), [i["num_threads"] for i in threadpool_info()
                                                  if i["internal_api"] == "openblas" and "numpy" in i["filepath"]])
atexit.register(report)
from orokit.cli.main import main
sys.argv = ["orokit", *sys.argv[1:]]
main()
"""


def test_console_script_runs_analyze_with_one_blas_thread(tmp_path):
    """``orokit analyze`` sets ``OPENBLAS_NUM_THREADS=1`` before numpy loads (with two cores or more numpy's
    OpenBLAS started a worker thread that spun ~0.1 s beside the imports; analyze makes no BLAS call); a user's
    value stays; another command keeps OpenBLAS's default."""
    dem = str(_dem(tmp_path / "dem.tif"))
    args = ["-q", "analyze", dem, "--no-progress", "--min-prominence", "5", "-o"]
    assert _console(*args, str(tmp_path / "a"), script=BLAS) == "1 [1]"
    assert _console(*args, str(tmp_path / "b"), script=BLAS, env={"OPENBLAS_NUM_THREADS": "2"}).startswith("2 [")
    assert _console("data", "list", script=BLAS).startswith("None ")


@pytest.mark.parametrize("args", [["--version"], ["data", "list"]])
def test_console_script_other_commands_keep_the_defaults(args):
    assert _console(*args) == f"None {sys.getswitchinterval()} [] None"  # this process's: Python's default


#: ``python -m orokit.cli.main``: runpy runs the module as ``__main__``, a second copy of ``orokit.cli.main``
MODULE = SCRIPT.replace("from orokit.cli.main import main\n", "import runpy\n").replace(
    "main()\n", "runpy.run_module('orokit.cli.main', run_name='__main__', alter_sys=True)\n")


def test_python_m_is_orokits_own_process_for_every_command_module(tmp_path):
    """``python -m orokit.cli.main analyze`` gets all of analyze's settings, the LLVM drop included: the
    commands ask :func:`owns_process` of the imported ``orokit.cli.main``, not of the ``__main__`` copy
    (before: ``['arenas 2'] system``, the drop skipped)."""
    assert "runpy.run_module" in MODULE and "import main" not in MODULE
    dem = str(_dem(tmp_path / "dem.tif"))
    args = ["-q", "analyze", dem, "--no-progress", "--min-prominence", "5", "-o", str(tmp_path / "m")]
    assert _analyze_calls(_console(*args, script=MODULE)) == (ANALYZE_CALLS, "system")


#: the console script's process with numba's target start held until the read begins (10 s at most), and the
#: raster-size bound of the read's wait for that start given as the first argument
ORDER = SCRIPT.replace("import orokit.io.dem as dem\n", """import threading
import orokit.analysis, orokit.cli.analyze
orokit.cli.analyze.READ_BESIDE_TARGET_CELLS = int(sys.argv.pop(1))
reading = threading.Event()
_start = orokit.analysis.start_numba_target
def start_numba_target():
    reading.wait(10)
    calls.append("target")
    _start()
orokit.analysis.start_numba_target = start_numba_target
import orokit.io.dem as dem
""").replace("calls.append(\"read\"))", "calls.append(\"read\"), reading.set())")


def test_a_large_raster_is_read_beside_numbas_start(tmp_path):
    """A raster of more than ``READ_BESIDE_TARGET_CELLS`` cells is read without waiting for numba's target to
    start (its ~0.25 CPU s of Python beside the read: the 2-core run's start); a smaller one after it, LLVM's
    pages dropped before the read (tested above). The 3,000-cell DEM stands for either by the bound."""
    assert ORDER.count("reading.set()") == 1 and ORDER.count("READ_BESIDE_TARGET_CELLS") == 1
    dem = str(_dem(tmp_path / "dem.tif"))
    args = ["-q", "analyze", dem, "--no-progress", "--min-prominence", "5", "-o"]
    calls = [c for c in _analyze_calls(_console("2999", *args, str(tmp_path / "a"), script=ORDER), 1)[0]
             if c in ("target", "read")]
    assert calls == ["read", "target"]
    calls = [c for c in _analyze_calls(_console("3000", *args, str(tmp_path / "b"), script=ORDER))[0]
             if c in ("target", "read")]
    assert calls == ["target", "read"]


#: the console script's process with the raster-size bound given as the first argument, recording when the
#: engine's strips start (the main thread's ``saddle_graph``) and when the loader's other kernels (its tiny
#: ``orometry``, after the strips' kernels) are loaded; with "hold" second, that loading waits (10 s at most)
#: for the strips to start
STRIPS = SCRIPT.replace("import orokit.io.dem as dem\n", """import threading
import orokit.cli.analyze
from orokit.topology import engine
orokit.cli.analyze.READ_BESIDE_TARGET_CELLS = int(sys.argv.pop(1))
hold = sys.argv.pop(1) == "hold"
strips = threading.Event()
_graph, _orometry = engine.saddle_graph, engine.orometry
def saddle_graph(*a, **k):
    if threading.current_thread() is threading.main_thread():
        calls.append("strips")
        strips.set()
    return _graph(*a, **k)
def orometry(*a, **k):
    if hold:
        strips.wait(10)
    out = _orometry(*a, **k)
    calls.append("kernels")
    return out
engine.saddle_graph, engine.orometry = saddle_graph, orometry
import orokit.io.dem as dem
""")


def _strips_and_kernels(line: str, after_loader: int) -> list[str]:
    calls = _analyze_calls(line, after_loader)[0]
    # the pages of files dropped before the engine (after its kernels, or the strips') and before writing;
    # a smaller raster's before the read too
    assert calls.count("drop ") == 2 + after_loader and calls.index("drop ", calls.index("read")) < calls.index(
        "strips"), calls
    return [c for c in calls if c in ("strips", "kernels")]


def test_a_large_rasters_strips_start_beside_the_kernels_loading(tmp_path):
    """Above ``READ_BESIDE_TARGET_CELLS`` cells the engine's strips start once their own kernels are loaded, the
    loader's other kernels (the join's, the finalize's, the tables', held here until the strips start) loading
    beside them (the loader's ~0.1-0.4 CPU s after the read left a core idle); at the bound the engine starts
    after the loader, as before. The tables are the same. The 3,000-cell DEM stands for either by the bound."""
    assert STRIPS.count("READ_BESIDE_TARGET_CELLS") == 1 and STRIPS.count("strips.wait(10)") == 1
    dem = str(_dem(tmp_path / "dem.tif"))
    args = ["-q", "analyze", dem, "--no-progress", "--min-prominence", "5", "-o"]
    assert _strips_and_kernels(_console("2999", "hold", *args, str(tmp_path / "a"), script=STRIPS), 1) == [
        "strips", "kernels"]
    assert _strips_and_kernels(_console("3000", "free", *args, str(tmp_path / "b"), script=STRIPS), 2) == [
        "kernels", "strips"]
    for name in ("peaks.csv", "saddles.parquet"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()


def test_a_failing_kernel_loader_fails_the_command_at_any_size(tmp_path):
    """A loader that fails (before the strips' kernels) fails ``orokit analyze`` with its error, above the bound
    (the engine started beside it: it waits for no event in vain) and at it."""
    script = SCRIPT.replace("import orokit.io.dem as dem\n", """import orokit.analysis, orokit.cli.analyze
orokit.cli.analyze.READ_BESIDE_TARGET_CELLS = int(sys.argv.pop(1))
def load_kernels(**kwargs):
    raise RuntimeError("the loader failed")
orokit.analysis.load_kernels = load_kernels
import orokit.io.dem as dem
""")
    dem = str(_dem(tmp_path / "dem.tif"))
    for bound in ("2999", "3000"):
        res = subprocess.run([sys.executable, "-c", script, bound, "-q", "analyze", dem, "--no-progress", "-o",
                              str(tmp_path / bound)], capture_output=True, text=True, timeout=120)
        assert res.returncode != 0 and "the loader failed" in res.stderr, res.stderr
