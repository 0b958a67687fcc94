"""Threshold hillslopes: no slope of the raster steeper than a critical angle (talus fill)."""
from __future__ import annotations

import numpy as np

__all__ = ["limit_slope"]


def limit_slope(z: np.ndarray, cell_size_m: float, max_slope_deg: float, *, max_rounds: int = 100_000
                ) -> np.ndarray:
    """``z`` with every cell raised just enough that none lies more than ``tan(max_slope_deg)``
    x distance below any of its 8 neighbours (a copy, same dtype).

    Cells are only raised: the result is the smallest surface above ``z`` whose drop between
    8-neighbours is at most the critical slope (as scree fills the foot of a cliff), so no
    new maximum appears (a raised cell has a higher neighbour) and peaks, ridges and valley
    floors away from cliffs keep their heights. On a smooth slope the central-difference
    gradient is then at most the critical slope; on rough ground (different drops along the
    two axes) it may exceed it, up to sqrt(2) x.

    >>> z = np.array([[0.0, 0.0, 100.0, 0.0]])
    >>> limit_slope(z, 10.0, 45.0).tolist()
    [[80.0, 90.0, 100.0, 90.0]]
    """
    if not 0.0 < float(max_slope_deg) < 90.0:
        raise ValueError(f"max_slope_deg must be in (0, 90), got {max_slope_deg!r}")
    out = np.array(z, copy=True)
    s = float(np.tan(np.radians(max_slope_deg))) * float(cell_size_m)
    ny, nx = out.shape
    steps = []
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            if dr or dc:
                dst = (slice(max(dr, 0), ny + min(dr, 0)), slice(max(dc, 0), nx + min(dc, 0)))
                src = (slice(max(-dr, 0), ny + min(-dr, 0)), slice(max(-dc, 0), nx + min(-dc, 0)))
                steps.append((dst, src, out.dtype.type(s * np.hypot(dr, dc))))
    for _ in range(max_rounds):
        changed = False
        for dst, src, drop in steps:
            low = out[src] - drop
            m = low > out[dst]
            if m.any():
                out[dst][m] = low[m]
                changed = True
        if not changed:
            break
    return out
