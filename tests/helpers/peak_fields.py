"""Random peak fields for the per-disk statistics' brute-force tests."""
from __future__ import annotations

import numpy as np


def random_peak_field(seed: int, n: int, width_m: float, height_m: float):
    """``n`` peaks uniform in ``[0, width] x [0, height]``: x, y, elevation 100-3000 m, prominence 10 m + Exp(150 m)."""
    rng = np.random.default_rng(seed)
    x, y = rng.uniform(0, width_m, n), rng.uniform(0, height_m, n)
    z = rng.uniform(100, 3000, n)
    prom = rng.exponential(150, n) + 10
    return x, y, z, prom
