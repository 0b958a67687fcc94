"""The renderer's jobs on second threads: an error raised there comes out of the render (not lost, no hang)."""
from __future__ import annotations

import threading

import pytest

from helpers.trees import small_tree


class _JobFailed(RuntimeError):
    pass


def _fail(*args, **kwargs):
    raise _JobFailed(threading.current_thread().name)


@pytest.mark.parametrize("module, job", [("skeleton", "poisson_samples"), ("render", "power_law_noise"),
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
