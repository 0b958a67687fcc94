"""The block-maximum pyramid of the isolation search against a plain loop."""
from __future__ import annotations

import numpy as np
import pytest

from orokit.metrics import _kernels


def _reference(level0: np.ndarray) -> list[np.ndarray]:
    """Levels 1.. by the definition: each cell keeps the first value of its 2 x 2 block (cut at the
    edges) unless a later one, in raster order, is larger (so a NaN first cell stays NaN)."""
    levels = []
    src = level0
    while src.shape[0] > 1 or src.shape[1] > 1:
        h, w = (src.shape[0] + 1) // 2, (src.shape[1] + 1) // 2
        dst = np.empty((h, w), src.dtype)
        for r in range(h):
            for c in range(w):
                block = src[2 * r:2 * r + 2, 2 * c:2 * c + 2].ravel()
                m = block[0]
                for v in block[1:]:
                    if v > m:
                        m = v
                dst[r, c] = m
        levels.append(dst)
        src = dst
    return levels


def _levels(pyr) -> list[np.ndarray]:
    vals, offs, hs, ws = pyr
    return [vals[offs[k]:offs[k + 1]].reshape(hs[k], ws[k]) for k in range(1, hs.size)]


@pytest.mark.parametrize("shape", [(1, 1), (1, 7), (9, 1), (2, 2), (5, 8), (33, 17), (64, 64), (131, 70)])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_pyramid_matches_its_definition(shape, dtype):
    rng = np.random.default_rng(sum(shape))
    z = rng.integers(0, 6, size=shape).astype(dtype)  # many ties
    z[rng.random(shape) < 0.1] = np.nan
    z[rng.random(shape) < 0.05] = -np.inf
    want = _reference(z)
    vals, offs, hs, ws = _kernels.build_pyramid(z)
    assert vals.dtype == z.dtype
    assert list(hs) == [shape[0]] + [lv.shape[0] for lv in want]
    assert list(ws) == [shape[1]] + [lv.shape[1] for lv in want]
    got = _levels((vals, offs, hs, ws))
    assert len(got) == len(want)
    for g, w in zip(got, want):
        np.testing.assert_array_equal(g, w)
