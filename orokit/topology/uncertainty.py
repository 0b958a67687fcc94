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
                rng: np.random.Generator, min_prominence_m: float, outside: str = "unknown") -> MonteCarloResult:
    """Re-run the exact engine on ``samples`` noisy copies of ``z`` and match the peaks.

    In each realisation ``z + e`` (``e`` from :func:`correlated_noise`; NaN cells stay
    NaN), a given peak is matched to the nearest realisation peak with prominence >=
    ``min_prominence_m`` within the ellipse of half-axes ``radius_cells`` (rows, cols),
    ties to the more prominent one.
    """
    from scipy.spatial import cKDTree

    from orokit.topology.engine import orometry

    if samples < 1:
        raise InputError(f"the number of Monte Carlo samples must be >= 1, got {samples}")
    ry, rx = (max(float(v), 1.0) for v in radius_cells)
    n = len(peak_row)
    pts = np.column_stack([np.asarray(peak_row) / ry, np.asarray(peak_col) / rx])
    out = np.full((samples, n), np.nan)
    emax = np.zeros(samples)
    for i in range(samples):
        e = correlated_noise(z.shape, sigma_m, corr_cells, rng)
        zr = np.ascontiguousarray(z + e)
        emax[i] = float(np.nanmax(np.abs(np.where(np.isnan(z), 0.0, e)))) if e.size else 0.0
        core = orometry(zr, min_prominence_m=min_prominence_m, outside=outside)
        if core.n_kept == 0 or n == 0:
            continue
        q = np.column_stack([core.peak_row / ry, core.peak_col / rx])
        tree = cKDTree(q)
        dist, idx = tree.query(pts, k=min(4, core.n_kept), distance_upper_bound=1.0 + 1e-9)
        dist, idx = dist.reshape(n, -1), idx.reshape(n, -1)
        found = np.isfinite(dist[:, 0])
        best = np.full(n, -1)
        for j in np.flatnonzero(found):
            cand = idx[j][np.isfinite(dist[j]) & (dist[j] <= dist[j, 0] + 1e-12)]
            best[j] = cand[np.argmax(core.prominence[cand])]
        out[i, found] = core.prominence[best[found]]
    exists = np.isfinite(out)
    with np.errstate(all="ignore"):
        median = np.full(n, np.nan)
        any_found = exists.any(axis=0)
        if any_found.any():
            median[any_found] = np.nanmedian(out[:, any_found], axis=0)
    return MonteCarloResult(exists.mean(axis=0), median, out, emax)
