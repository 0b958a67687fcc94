"""Prominence under DEM error: guaranteed bounds and Monte Carlo (issue 16).

A DEM whose error is at most ``k * sigma`` everywhere moves every elevation by at most
that much, so a peak's prominence (peak minus key saddle) moves by at most
``2 k sigma`` (``k sigma`` for a landmass high point, whose prominence is its
elevation): the bounds of :func:`prominence_bounds` hold for every such error field
(stability of persistence). :func:`monte_carlo` draws spatially correlated Gaussian
error fields (FFT filter, :func:`correlated_noise`), re-runs the exact engine on each
and reports, per peak, the share of realisations in which a peak with prominence >= the
threshold lies within one correlation length, and the median of its prominence.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from orokit.errors import InputError

__all__ = ["prominence_bounds", "correlated_noise", "monte_carlo", "MonteCarloResult"]


def prominence_bounds(prominence: np.ndarray, is_root: np.ndarray, sigma_m: float,
                      k: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """Guaranteed ``(low, high)`` prominence for any DEM error of at most ``k * sigma_m``.

    A peak and its key saddle each move by at most ``k sigma``: the prominence by at
    most ``2 k sigma`` (``k sigma`` for a root, whose prominence is its elevation);
    ``low`` is clipped at 0.

    >>> lo, hi = prominence_bounds(np.array([50.0, 3.0, 900.0]), np.array([False, False, True]), 2.0)
    >>> lo.tolist(), hi.tolist()
    ([42.0, 0.0, 896.0], [58.0, 11.0, 904.0])
    """
    if not (np.isfinite(sigma_m) and sigma_m >= 0):
        raise InputError(f"the DEM error sigma must be a finite length >= 0 (metres), got {sigma_m!r}")
    if not (np.isfinite(k) and k > 0):
        raise InputError(f"the error multiple k must be a finite number > 0, got {k!r}")
    prom = np.asarray(prominence, dtype=np.float64)
    shift = np.where(np.asarray(is_root, bool), 1.0, 2.0) * k * sigma_m
    return np.maximum(prom - shift, 0.0), prom + shift


def correlated_noise(shape: tuple[int, int], sigma_m: float, corr_cells: tuple[float, float],
                     rng: np.random.Generator) -> np.ndarray:
    """Gaussian error field of standard deviation ``sigma_m`` and correlation length ``corr_cells``.

    White noise filtered by FFT with a Gaussian kernel: the covariance is
    ``exp(-(dy/Ly)^2 - (dx/Lx)^2)`` (so ``L = corr_cells`` (rows, cols) is the
    e-folding distance); 0 gives white noise. The field is computed on a grid padded
    by ``2 L`` (no wrap-around across the edges) and scaled to the exact sample
    standard deviation ``sigma_m``.
    """
    ly, lx = (float(v) for v in corr_cells)
    h, w = shape
    if sigma_m == 0:
        return np.zeros(shape)
    if ly <= 0 and lx <= 0:
        field = rng.standard_normal(shape)
    else:
        py, px = int(np.ceil(2 * ly)), int(np.ceil(2 * lx))
        white = rng.standard_normal((h + 2 * py, w + 2 * px))
        fy = np.fft.fftfreq(white.shape[0])[:, None]
        fx = np.fft.rfftfreq(white.shape[1])[None, :]
        # a Gaussian kernel of std s = L / 2 (transfer exp(-2 pi^2 s^2 f^2)) gives the covariance
        # exp(-r^2 / (4 s^2)) = exp(-r^2 / L^2)
        gain = np.exp(-0.5 * np.pi ** 2 * ((ly * fy) ** 2 + (lx * fx) ** 2))
        field = np.fft.irfft2(np.fft.rfft2(white) * gain, s=white.shape)[py:py + h, px:px + w]
    std = field.std()
    return field * (sigma_m / std) if std > 0 else np.zeros(shape)


@dataclass(frozen=True)
class MonteCarloResult:
    """Per-peak outcome of :func:`monte_carlo` (arrays aligned with the peaks given).

    Attributes
    ----------
    p_exists : share of realisations with a peak of prominence >= the threshold within
        the matching radius.
    prominence_median : median prominence of the matched peak over the realisations
        where one exists (NaN if none).
    prominence_samples : (samples, peaks) prominence of the matched peak (NaN: none).
    max_abs_error_m : largest |error| of each realisation.
    """

    p_exists: np.ndarray
    prominence_median: np.ndarray
    prominence_samples: np.ndarray
    max_abs_error_m: np.ndarray


def monte_carlo(z: np.ndarray, peak_row: np.ndarray, peak_col: np.ndarray, *, sigma_m: float,
                corr_cells: tuple[float, float], radius_cells: tuple[float, float], samples: int,
                rng: np.random.Generator, min_prominence_m: float, outside: str = "unknown",
                peak_prominence: np.ndarray | None = None, workers: int | None = None) -> MonteCarloResult:
    """Re-run the exact engine on ``samples`` noisy copies of ``z`` and match the peaks.

    In each realisation ``z + e`` (``e`` from :func:`correlated_noise`; NaN cells stay
    NaN), a given peak is matched to a realisation peak with prominence >=
    ``min_prominence_m`` within the ellipse of half-axes ``radius_cells`` (rows, cols):
    with ``peak_prominence`` (the peaks' own prominences), the one whose prominence is
    closest to it, so that a more prominent neighbour is not taken for a small peak that
    survived; without, the nearest (ties to the more prominent).

    Realisation i draws its error from the i-th child of ``rng`` (``rng.spawn``), so the
    result does not depend on ``workers``: the number of realisations run at once in
    threads (default: the CPU count; the engine releases the GIL).
    """
    import os
    import threading
    from concurrent.futures import ThreadPoolExecutor

    from orokit.topology.engine import orometry

    if samples < 1:
        raise InputError(f"the number of Monte Carlo samples must be >= 1, got {samples}")
    ry, rx = (max(float(v), 1.0) for v in radius_cells)
    n = len(peak_row)
    pts = np.column_stack([np.asarray(peak_row) / ry, np.asarray(peak_col) / rx])
    target = None if peak_prominence is None else np.asarray(peak_prominence, dtype=float)
    out = np.full((samples, n), np.nan)
    emax = np.zeros(samples)
    rngs = rng.spawn(samples)
    nan = np.isnan(z)
    engine_lock = _engine_lock(threading)

    def one(i: int) -> None:
        e = correlated_noise(z.shape, sigma_m, corr_cells, rngs[i])
        zr = np.ascontiguousarray(z + e)
        emax[i] = float(np.max(np.abs(np.where(nan, 0.0, e)))) if e.size else 0.0
        del e
        with engine_lock:
            core = orometry(zr, min_prominence_m=min_prominence_m, outside=outside)
        del zr
        if core.n_kept > 0 and n > 0:
            out[i] = _match(pts, core.peak_row / ry, core.peak_col / rx, core.prominence, target)

    workers = max(1, min(samples, workers if workers is not None else (os.cpu_count() or 1)))
    if workers == 1:
        for i in range(samples):
            one(i)
    else:
        with ThreadPoolExecutor(workers) as pool:
            list(pool.map(one, range(samples)))
    exists = np.isfinite(out)
    with np.errstate(all="ignore"):
        median = np.full(n, np.nan)
        any_found = exists.any(axis=0)
        if any_found.any():
            median[any_found] = np.nanmedian(out[:, any_found], axis=0)
    return MonteCarloResult(exists.mean(axis=0), median, out, emax)


def _engine_lock(threading: Any) -> Any:
    """A lock around the engine unless numba's threading layer takes concurrent calls
    (``omp``, ``tbb``; not ``workqueue``)."""
    import contextlib

    import numba

    try:
        layer = numba.threading_layer()
    except ValueError:  # no parallel function has run yet: the layer is not known
        layer = ""
    return contextlib.nullcontext() if layer in ("omp", "tbb") else threading.Lock()


def _match(pts: np.ndarray, q_row: np.ndarray, q_col: np.ndarray, q_prom: np.ndarray,
           target: np.ndarray | None) -> np.ndarray:
    """Prominence of the realisation peak matched to each of ``pts`` (NaN: none within 1)."""
    from scipy.spatial import cKDTree

    n = len(pts)
    res = np.full(n, np.nan)
    tree = cKDTree(np.column_stack([q_row, q_col]))
    k = min(8, len(q_row))
    dist, idx = tree.query(pts, k=k, distance_upper_bound=1.0 + 1e-9)
    dist, idx = dist.reshape(n, -1), idx.reshape(n, -1)
    for j in np.flatnonzero(np.isfinite(dist[:, 0])):
        ok = np.isfinite(dist[j])
        cand, d = idx[j][ok], dist[j][ok]
        if target is None:
            near = cand[d <= d[0] + 1e-12]
            res[j] = q_prom[near[np.argmax(q_prom[near])]]
        else:
            gap = np.abs(q_prom[cand] - target[j])
            res[j] = q_prom[cand[np.lexsort((d, gap))[0]]]
    return res
