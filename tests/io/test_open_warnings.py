"""Opening a raster without georeference: rasterio's warning hidden in orokit's open only, from any thread,
without touching another thread's warning filters or recorder (``warnings.catch_warnings`` is process-wide)."""
from __future__ import annotations

import threading
import warnings

import numpy as np
import pytest
import rasterio
import rasterio.errors

from orokit.io import dem


def _plain_tif(path):
    with warnings.catch_warnings():  # rasterio warns when it writes a raster without georeference
        warnings.simplefilter("ignore", rasterio.errors.NotGeoreferencedWarning)
        with rasterio.open(path, "w", driver="GTiff", width=8, height=8, count=1, dtype="float32") as dst:
            dst.write(np.arange(64, dtype=np.float32).reshape(1, 8, 8))
    return str(path)


def test_open_hides_the_warning_only_in_its_own_call(tmp_path):
    path = _plain_tif(tmp_path / "plain.tif")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a filter added after orokit's: still no warning from its open
        dem._open_dataset(path).close()
        t = threading.Thread(target=lambda: dem._open_dataset(path).close())
        t.start()
        t.join()
    with pytest.warns(rasterio.errors.NotGeoreferencedWarning):  # a caller's own open still warns
        rasterio.open(path).close()


def test_open_in_a_thread_leaves_the_other_threads_warning_state(tmp_path, monkeypatch):
    """The main thread's recorder ends while a worker thread is opening a file: the open still warns
    nothing, and afterwards a warning is not recorded in the ended recorder (before: the worker's
    ``catch_warnings`` put that recorder back for good, and its open warned once the main thread's
    filters were restored: an error under ``-W error``)."""
    path = _plain_tif(tmp_path / "plain.tif")
    dem._open_dataset(path).close()  # orokit's filter is in place before the main thread's recorder copies them
    inside, go_on = threading.Event(), threading.Event()
    real_open = rasterio.open

    def slow_open(*args, **kwargs):
        inside.set()
        go_on.wait(30)
        return real_open(*args, **kwargs)

    monkeypatch.setattr(rasterio, "open", slow_open)
    errors: list[BaseException] = []

    def worker() -> None:
        try:
            dem._open_dataset(path).close()
        except BaseException as exc:  # noqa: BLE001 - reported by the test
            errors.append(exc)

    with warnings.catch_warnings(record=True) as ended:
        t = threading.Thread(target=worker)
        t.start()
        assert inside.wait(30)
    go_on.set()
    t.join(30)
    assert not errors
    with warnings.catch_warnings(record=True) as now:
        warnings.simplefilter("always")
        warnings.warn("after the open", UserWarning)
    assert [str(w.message) for w in now] == ["after the open"]
    with warnings.catch_warnings():  # the filters only: shown by whatever shows warnings now
        warnings.simplefilter("always")
        warnings.warn("after both", UserWarning)
    assert ended == []  # not by the ended recorder


def test_the_filters_can_still_be_deep_copied(tmp_path):
    """orokit's filter (its thread-local flag cannot be copied) survives a caller's deep copy of the filters."""
    import copy

    dem._open_dataset(_plain_tif(tmp_path / "plain.tif")).close()
    assert copy.deepcopy(warnings.filters) == warnings.filters


def test_the_filters_survive_scikit_learns_parallel_and_pickling(tmp_path):
    """scikit-learn's ``Parallel`` replays the caller's filters in each task with
    ``filterwarnings(message=f.pattern)`` (the region classifier: AttributeError there, the realism
    record of session 15 stopped), and a process pool pickles them."""
    import pickle

    from sklearn.utils.parallel import Parallel, delayed

    dem._open_dataset(_plain_tif(tmp_path / "plain.tif")).close()
    assert pickle.loads(pickle.dumps(warnings.filters)) == warnings.filters
    assert Parallel(n_jobs=1)(delayed(abs)(v) for v in (-1, -2)) == [1, 2]
    with pytest.warns(rasterio.errors.NotGeoreferencedWarning):  # in a task the filter matches nothing
        Parallel(n_jobs=1)(delayed(warnings.warn)("x", rasterio.errors.NotGeoreferencedWarning) for _ in (0,))


def test_a_filter_pushed_and_popped_by_other_code_stays_its_own(tmp_path):
    """Code that adds a filter of another category and pops index 0 afterwards (POT's ``get_params``)
    pops its own filter even when an orokit open runs between the two (before: the open moved orokit's
    filter to the front, the pop took it and the other filter stayed for good)."""
    path = _plain_tif(tmp_path / "plain.tif")
    with warnings.catch_warnings():
        dem._open_dataset(path).close()
        warnings.filterwarnings("always", category=DeprecationWarning)
        dem._open_dataset(path).close()  # another thread's open, in real use
        popped = warnings.filters.pop(0)
        assert popped[2] is DeprecationWarning
        assert dem._NOT_GEOREFERENCED.entry in warnings.filters
        warnings.simplefilter("error", UserWarning)  # one that takes the warning: orokit's goes in front
        dem._open_dataset(path).close()
        assert warnings.filters[0] is dem._NOT_GEOREFERENCED.entry
