"""The renderer's jobs on second threads: an error raised there comes out of the render (not lost, no hang)."""
from __future__ import annotations

import threading

import numpy as np
import pytest

from helpers.trees import small_tree


class _JobFailed(RuntimeError):
    pass


def _fail(*args, **kwargs):
    raise _JobFailed(threading.current_thread().name)


@pytest.mark.parametrize("module, job", [("skeleton", "poisson_darts"), ("render", "power_law_noise"),
                                         ("render", "_node_distance")])
def test_an_error_in_a_job_on_a_second_thread_is_raised_by_the_render(monkeypatch, module, job):
    from orokit.raster import render, skeleton
    from orokit.raster.params import RenderParams

    monkeypatch.setattr({"skeleton": skeleton, "render": render}[module], job, _fail)
    before = {t.name for t in threading.enumerate()}
    with pytest.raises(_JobFailed) as err:
        render.render_elevation(small_tree(), cell_size_m=25.0, erosion=False, params=RenderParams(lam=200.0), rng=5)
    assert str(err.value).startswith("orokit-")  # it was raised on the job's own thread
    # the render's pools are shut down: their threads end (none is left waiting for work)
    for t in threading.enumerate():
        if t.name.startswith("orokit-") and t.name not in before:
            t.join(timeout=60)
            assert not t.is_alive()


class _ThreadSpy(np.random.Generator):
    """A Generator that records the name of every thread that touches it."""

    threads: set[str] = set()

    def __getattribute__(self, name):
        _ThreadSpy.threads.add(threading.current_thread().name)
        return super().__getattribute__(name)


def test_the_skeleton_draws_from_its_generator_on_the_calling_thread_only():
    """The darts run on a second thread, but their seed is drawn by the caller: no draw from the render's
    Generator can interleave with another thread's, so no output can depend on the threads' timing."""
    from orokit.raster.params import RenderParams
    from orokit.raster.skeleton import build_skeleton

    _ThreadSpy.threads = set()
    tree = small_tree()
    build_skeleton(tree, extent=(0.0, 0.0, 8000.0, 8000.0), params=RenderParams(lam=200.0),
                   rng=_ThreadSpy(np.random.PCG64(5)))
    assert _ThreadSpy.threads == {threading.current_thread().name}


def test_the_render_imports_xarray_on_a_second_thread_and_returns_a_dataarray():
    """``orokit render`` loads no xarray, dask or rioxarray before the render (they are ~0.6 CPU s);
    the render imports them on a second thread and returns a georeferenced DataArray."""
    import subprocess
    import sys
    from pathlib import Path

    code = """
import sys, threading
import orokit.cli.render, orokit.raster.render  # what `orokit render` imports before the render
print(sorted(m for m in ("xarray", "dask", "rioxarray") if m in sys.modules))
import builtins
first = {}
real_import = builtins.__import__
def spy(name, *args, **kwargs):
    if name.startswith("xarray") and "xarray" not in first:
        first["xarray"] = threading.current_thread().name
    return real_import(name, *args, **kwargs)
builtins.__import__ = spy
sys.path.insert(0, sys.argv[1])
from helpers.trees import small_tree
from orokit.raster.params import RenderParams
da = orokit.raster.render.render_elevation(small_tree(crs="EPSG:32633"), cell_size_m=50.0, erosion=False,
                                           params=RenderParams(lam=200.0), rng=1)
builtins.__import__ = real_import
print(first.get("xarray"), type(da).__name__, da.rio.crs.to_epsg(), da.rio.transform().a)
"""
    tests = str(Path(__file__).resolve().parents[1])
    res = subprocess.run([sys.executable, "-c", code, tests], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    before, after = res.stdout.strip().splitlines()[-2:]
    assert before == "[]"
    assert after.startswith("orokit-imports") and after.split()[1:] == ["DataArray", "32633", "50.0"]
