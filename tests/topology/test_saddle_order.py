"""engine.saddle_order: the 4-key lexsort of the edges, by one 64-bit key when elevations are float32."""
from __future__ import annotations

import numpy as np
import pytest

from orokit.topology.engine import saddle_order


def _assert_lexsort_order(ea, eb, ez, cells, radix, t):
    """saddle_order gives the edges in the order of the lexsort by (-z, cell, a, b)."""
    want = np.lexsort((eb, ea, cells, -ez))
    got = saddle_order(ea, eb, ez, cells, radix=radix)
    edges = np.stack([ea, eb, cells])
    np.testing.assert_array_equal(edges[:, got], edges[:, want], err_msg=f"case {t}")


@pytest.mark.parametrize("radix", [False, True])
def test_saddle_order_is_the_lexsort(radix):
    rng = np.random.default_rng(0)
    n_fast = 0
    for t in range(300):
        m = int(rng.integers(0, 400))
        cells = rng.integers(0, 50, m).astype(np.int64)  # many edges share a cell (monkey saddles)
        z = rng.integers(-3, 4, 60).astype(np.float32) * np.float32(0.5)
        z[rng.random(60) < 0.2] *= -1  # -0.0 beside 0.0: one elevation
        ez = z[cells].astype(np.float64)
        if t % 5 == 0:
            ez = ez + 1e-9 * (t % 2)  # not float32 (odd t): the lexsort itself
        else:
            n_fast += m > 0
        ea = rng.integers(0, 10, m)
        eb = ea + rng.integers(1, 5, m)
        _assert_lexsort_order(ea, eb, ez, cells, radix, t)
    assert n_fast > 200


@pytest.mark.parametrize("radix", [False, True])
def test_saddle_order_with_ties_to_side_cells_is_the_lexsort(radix):
    """The tiled engine's root: edges above every saddle (+inf) keyed ``-1 - cell`` sort first, by
    one 64-bit key too; the order is the stable lexsort's, index for index."""
    from orokit.topology._kernels import saddle_key

    rng = np.random.default_rng(1)
    for t in range(300):
        m = int(rng.integers(1, 400))
        cells = rng.integers(0, 2**32 - 1 if t % 3 == 0 else 40, m).astype(np.int64)
        z = (rng.integers(-3, 4, m).astype(np.float32) * np.float32(0.5)).astype(np.float64)
        side = rng.random(m) < 0.3
        z[side] = np.inf
        cells[side] = -1 - cells[side]
        ea = rng.integers(0, 6, m)
        eb = ea + rng.integers(1, 3, m)  # repeated (ea, eb, cell) edges: the index decides
        want = np.lexsort((eb, ea, cells, -z))
        np.testing.assert_array_equal(saddle_order(ea, eb, z, cells, radix=radix), want, err_msg=f"case {t}")
        bits = z.astype(np.float32).view(np.uint32)
        assert saddle_key(bits, cells, z).size == m  # the one-key path, not the lexsort


def test_saddle_key_falls_back_outside_32_bits():
    """Keys that do not fit (a finite saddle with a negative key, inf edges with keys of both signs,
    a cell >= 2**32) take the lexsort: same order."""
    from orokit.topology._kernels import saddle_key

    up = np.arange(4, dtype=np.uint32)
    cases = [
        (np.array([1.0, 2.0, np.inf, 3.0]), np.array([0, -5, -1, 2])),
        (np.array([1.0, np.inf, np.inf, 3.0]), np.array([0, -5, 4, 2])),
        (np.array([1.0, 2.0, 2.0, 3.0]), np.array([0, 2**32, 4, 2])),
    ]
    for ez, ekey in cases:
        assert saddle_key(up, ekey, ez).size == 0
        ea, eb = np.array([0, 1, 2, 0]), np.array([1, 2, 3, 3])
        np.testing.assert_array_equal(saddle_order(ea, eb, ez, ekey), np.lexsort((eb, ea, ekey, -ez)))


def test_radix_argsort_is_a_stable_argsort_and_sorts_the_keys():
    """Keys spread over all 64 bits, in a narrow range (digits every key shares: skipped passes),
    with many repeats (stability), and the sizes 0, 1 and 2."""
    from orokit.topology._kernels import radix_argsort

    rng = np.random.default_rng(2)
    for t in range(60):
        m = [0, 1, 2][t] if t < 3 else int(rng.integers(3, 3000))
        if t % 3 == 0:
            key = rng.integers(0, 2**63, m, dtype=np.uint64) * np.uint64(2) + rng.integers(0, 2, m, dtype=np.uint64)
        elif t % 3 == 1:
            key = np.uint64(0xFFFF0000_00000000) + rng.integers(0, 3000, m, dtype=np.uint64)
        else:
            key = rng.integers(0, 7, m, dtype=np.uint64) << np.uint64(40)
        want = np.argsort(key, kind="stable")
        sorted_key = key.copy()
        got = radix_argsort(sorted_key)
        np.testing.assert_array_equal(got, want, err_msg=f"case {t}")
        np.testing.assert_array_equal(sorted_key, key[want])


def test_merge_sorted_halves_is_the_stable_argsort():
    """Two halves, each radix-sorted, merged: the whole key's stable argsort, the key sorted in place
    (repeats within and across the halves, halves of sizes 0 and 1)."""
    from orokit.topology._kernels import merge_sorted_halves, radix_argsort

    rng = np.random.default_rng(3)
    for t in range(80):
        m = [0, 1, 2, 3][t] if t < 4 else int(rng.integers(4, 3000))
        key = rng.integers(0, [5, 2**40, 2**63][t % 3], m, dtype=np.uint64)
        h = m // 2 if t % 4 else int(rng.integers(0, m + 1))
        work = key.copy()
        first, second = radix_argsort(work[:h]), radix_argsort(work[h:])
        got = merge_sorted_halves(work, first, second, h)
        np.testing.assert_array_equal(got, np.argsort(key, kind="stable"), err_msg=f"case {t}")
        np.testing.assert_array_equal(work, np.sort(key))


def test_saddle_order_on_two_threads_is_the_lexsort(monkeypatch):
    """The finalize's sort as two halves on two threads (every size here) gives the lexsort's order."""
    from orokit.topology import engine

    monkeypatch.setattr(engine, "PARALLEL_SORT_KEYS", 2)
    monkeypatch.setattr(engine, "_threads", lambda: 2)
    rng = np.random.default_rng(4)
    for t in range(100):
        m = int(rng.integers(0, 3000))
        cells = rng.integers(0, 200, m).astype(np.int64)  # monkey saddles across the halves
        z = rng.integers(-3, 4, 300).astype(np.float32) * np.float32(0.5)
        ez = z[cells].astype(np.float64)
        ea = rng.integers(0, 50, m)
        eb = ea + rng.integers(1, 5, m)
        _assert_lexsort_order(ea, eb, ez, cells, True, t)
