"""The chunked engine on a dask.distributed cluster (2 worker processes)."""
from __future__ import annotations

import os
import signal
import threading
import time

import numpy as np
import pytest

import orokit

from helpers.ridges import ridge_set

pytestmark = pytest.mark.cluster


@pytest.fixture(scope="module")
def cluster():
    """A cluster of two worker processes; the test process's environment is put back afterwards (a Nanny
    leaves its ``distributed.nanny.pre-spawn-environ`` in its own process's environment for good:
    ``MALLOC_TRIM_THRESHOLD_``, ``OMP_NUM_THREADS``, ``PYTHONHASHSEED``, which every process a later test of
    the same xdist worker starts inherited)."""
    import distributed  # a hard dependency (dask[distributed]): a missing install must fail, not skip

    saved = dict(os.environ)
    try:
        with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                                      memory_limit="2GiB") as cl, distributed.Client(cl) as client:
            yield cl, client
    finally:
        for name in set(os.environ) - set(saved):
            del os.environ[name]
        os.environ.update(saved)


def _terrain(shape=(400, 500), seed=7):
    rng = np.random.default_rng(seed)
    z = rng.normal(size=shape).cumsum(0).cumsum(1)
    z += 25 * rng.normal(size=shape)
    return z.astype(np.float32)


def _same(a, b):
    cols = [c for c in a.peaks.columns if c != "geometry"]
    assert a.peaks[cols].equals(b.peaks[cols])  # line and prominence parents included
    assert ridge_set(a.tree) == ridge_set(b.tree)


def test_local_cluster_equals_in_memory(cluster, make_dem):
    _, client = cluster
    dem = make_dem(_terrain())
    a = orokit.analyze(dem, min_prominence_m=20)
    b = orokit.analyze(dem, min_prominence_m=20, chunks=(90, 110), scheduler=client)
    assert len(a.peaks) > 20
    _same(a, b)
    # by scheduler address too (what `orokit analyze --scheduler tcp://...` does)
    c = orokit.analyze(dem, min_prominence_m=20, chunks=128, scheduler=client.scheduler.address)
    _same(a, c)


def test_depressions_on_a_local_cluster(cluster, make_dem):
    """Depressions with area_m2 (the chunked pass) on the cluster equal the in-memory table."""
    _, client = cluster
    z = np.round(_terrain((150, 170), seed=3) / 5)
    dem = make_dem(z)
    a = orokit.analyze(dem, min_prominence_m=2, isolation=False, depressions=True).depressions
    b = orokit.analyze(dem, min_prominence_m=2, isolation=False, depressions=True, chunks=(40, 60),
                       scheduler=client).depressions
    area = a["area_m2"].to_numpy()
    assert len(a) > 10 and np.isfinite(area).sum() > 10
    cols = [c for c in a.columns if c not in ("geometry", "area_m2")]
    assert a[cols].equals(b[cols])
    np.testing.assert_allclose(b["area_m2"].to_numpy(), area, rtol=1e-12, atol=0)  # another summation order


def test_killed_worker_run_still_exact(cluster, make_dem):
    """A worker killed mid-run: its tasks are recomputed elsewhere and the result is identical."""
    cl, client = cluster
    dem = make_dem(_terrain((900, 900), seed=11))
    a = orokit.analyze(dem, min_prominence_m=20)
    out = {}

    def run():
        out["r"] = orokit.analyze(dem, min_prominence_m=20, chunks=90, scheduler=client)

    t = threading.Thread(target=run)
    t.start()
    killed = False
    deadline = time.time() + 60
    while time.time() < deadline and t.is_alive():
        processing = client.processing()
        busy = [w for w, tasks in processing.items() if tasks]
        if busy:
            pid = client.run(os.getpid, workers=[busy[0]])[busy[0]]
            os.kill(pid, signal.SIGKILL)
            killed = True
            break
        time.sleep(0.01)
    t.join(timeout=120)
    assert killed, "the run finished before a worker could be killed"
    assert "r" in out
    _same(a, out["r"])
