"""engine.saddle_order: the 4-key lexsort of the edges, by one 64-bit key when elevations are float32."""
from __future__ import annotations

import numpy as np

from orokit.topology.engine import saddle_order


def test_saddle_order_is_the_lexsort():
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
        want = np.lexsort((eb, ea, cells, -ez))
        got = saddle_order(ea, eb, ez, cells)
        edges = np.stack([ea, eb, cells])
        np.testing.assert_array_equal(edges[:, got], edges[:, want], err_msg=f"case {t}")
    assert n_fast > 200
