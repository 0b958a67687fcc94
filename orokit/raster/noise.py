"""Multi-fractal value noise with a bounded amplitude (paper §6.3: below eps)."""
from __future__ import annotations

import numpy as np
from scipy import ndimage

from orokit._typing import SeedLike

__all__ = ["fractal_noise", "falloff"]


def _octave(shape: tuple[int, int], cells_per_node: float, rng: np.random.Generator) -> np.ndarray:
    ny, nx = shape
    gy = int(np.ceil(ny / cells_per_node)) + 2
    gx = int(np.ceil(nx / cells_per_node)) + 2
    g = rng.uniform(-1.0, 1.0, (gy, gx)).astype(np.float32)
    up = ndimage.zoom(g, cells_per_node, order=1, prefilter=False, grid_mode=False)
    oy = int(rng.integers(0, max(up.shape[0] - ny, 0) + 1))
    ox = int(rng.integers(0, max(up.shape[1] - nx, 0) + 1))
    return up[oy:oy + ny, ox:ox + nx]


def fractal_noise(
    shape: tuple[int, int],
    res: float,
    *,
    amplitude: float,
    largest_m: float = 2000.0,
    persistence: float = 0.55,
    roughness: np.ndarray | None = None,
    rng: SeedLike = None,
) -> np.ndarray:
    """Sum of value-noise octaves from ``largest_m`` down to 2 cells, ``|noise| <= amplitude``.

    Parameters
    ----------
    shape : (ny, nx) of the raster.
    res : cell size in metres.
    amplitude : bound on the absolute value of the result (metres).
    largest_m : wavelength of the first octave.
    persistence : amplitude ratio between successive octaves.
    roughness : optional array in [0, 1] of the raster's shape; octave k is scaled by
        ``(0.25 + 0.75 roughness) ** (k / n_octaves)`` (fine detail fades on low
        ground such as valley floors: a heterogeneous multi-fractal).
    rng : seed or generator.
    """
    rng = np.random.default_rng(rng)
    out = np.zeros(shape, np.float32)
    n_oct = max(int(np.floor(np.log2(max(largest_m / (2.0 * res), 1.0)))) + 1, 1)
    amp = 1.0
    for k in range(n_oct):
        wave = largest_m / 2.0**k
        o = _octave(shape, max(wave / res, 1.0), rng) * amp
        if roughness is not None:
            o *= np.power(0.25 + 0.75 * np.clip(roughness, 0.0, 1.0), k / n_oct).astype(np.float32)
        out += o
        amp *= persistence
    peak = float(np.max(np.abs(out))) if out.size else 0.0
    if peak > 0:
        out *= np.float32(amplitude / peak)
    return out


def falloff(r: np.ndarray) -> np.ndarray:
    """Compactly supported smooth fall-off ``g(r) = (1 - r^2)^3`` on [0, 1], 0 beyond."""
    r = np.clip(np.asarray(r, dtype=np.float32), 0.0, 1.0)
    return (1.0 - r * r) ** 3
