"""Threshold hillslopes: no slope of the raster steeper than a critical angle (talus fill)."""
from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["limit_slope"]


@njit(cache=True)
def _talus_sweeps(out: np.ndarray, s1: float, s2: float, max_rounds: int) -> None:
    """In place: forward and backward raster sweeps of ``out[i] = max(out[i], out[j] - drop(i, j))``
    over the 8 neighbours (drop ``s1`` along an axis, ``s2`` diagonally), repeated until nothing
    changes (a chamfer distance transform with initial values: one or two rounds)."""
    ny, nx = out.shape
    for _ in range(max_rounds):
        changed = False
        for i in range(ny):
            for j in range(nx):
                v = out[i, j]
                if j > 0 and out[i, j - 1] - s1 > v:
                    v = out[i, j - 1] - s1
                if i > 0:
                    if out[i - 1, j] - s1 > v:
                        v = out[i - 1, j] - s1
                    if j > 0 and out[i - 1, j - 1] - s2 > v:
                        v = out[i - 1, j - 1] - s2
                    if j < nx - 1 and out[i - 1, j + 1] - s2 > v:
                        v = out[i - 1, j + 1] - s2
                if v > out[i, j]:
                    out[i, j] = v
                    changed = True
        for i in range(ny - 1, -1, -1):
            for j in range(nx - 1, -1, -1):
                v = out[i, j]
                if j < nx - 1 and out[i, j + 1] - s1 > v:
                    v = out[i, j + 1] - s1
                if i < ny - 1:
                    if out[i + 1, j] - s1 > v:
                        v = out[i + 1, j] - s1
                    if j < nx - 1 and out[i + 1, j + 1] - s2 > v:
                        v = out[i + 1, j + 1] - s2
                    if j > 0 and out[i + 1, j - 1] - s2 > v:
                        v = out[i + 1, j - 1] - s2
                if v > out[i, j]:
                    out[i, j] = v
                    changed = True
        if not changed:
            return


def limit_slope(z: np.ndarray, cell_size_m: float, max_slope_deg: float, *, max_rounds: int = 100_000
                ) -> np.ndarray:
    """``z`` with every cell raised just enough that none lies more than ``tan(max_slope_deg)``
    x distance below any of its 8 neighbours (a copy, same dtype).

    Cells are only raised: the result is the smallest surface above ``z`` whose drop between
    8-neighbours is at most the critical slope (as scree fills the foot of a cliff), so no
    new maximum appears (a raised cell has a higher neighbour) and peaks, ridges and valley
    floors away from cliffs keep their heights. On a smooth slope the central-difference
    gradient is then at most the critical slope; on rough ground (different drops along the
    two axes) it may exceed it, up to sqrt(2) x. Computed by forward/backward raster sweeps
    (numba; a chamfer distance transform seeded with ``z``), so the cost is a few passes over the
    grid whatever the cliff heights.

    >>> z = np.array([[0.0, 0.0, 100.0, 0.0]])
    >>> limit_slope(z, 10.0, 45.0).tolist()
    [[80.0, 90.0, 100.0, 90.0]]
    """
    if not 0.0 < float(max_slope_deg) < 90.0:
        raise ValueError(f"max_slope_deg must be in (0, 90), got {max_slope_deg!r}")
    out = np.array(z, copy=True)
    if not np.issubdtype(out.dtype, np.floating):
        out = out.astype(np.float64)
    s = float(np.tan(np.radians(max_slope_deg))) * float(cell_size_m)
    if out.size:
        t = out.dtype.type
        _talus_sweeps(out, t(s), t(s * np.sqrt(2.0)), int(max_rounds))
    return out
