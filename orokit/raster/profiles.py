"""Hillslope and ridge profiles learned from real DEMs (issue 11: no planar facets).

The paper (§6.2) interpolates linearly between ridge and river, and along a ridge
between peak and saddle, which gives planar facets and too much mid-slope ground. These
profiles are the medians measured on the real DEMs of the tuning regions (alaska,
andes-chile, appalachians, gobi, himalaya-everest, norway) around their own Divide
Trees, at eps 30 m (``python benchmarks/profiles.py``):

- hillslope: ``f(u)`` = (h(p) - h(r)) / (h(q) - h(r)) against ``u = d(p, R) / (d(p, R) + d(p, T))``
  (0 on the river, 1 on the ridge), with h the real ground at p, at its nearest ridge
  point q and its nearest river point r: concave valley sides, about 0 over the lowest
  fifth, 0.5 at u = 0.62;
- ridge: ``g(t)`` = (h(x) - h(saddle)) / (h(peak) - h(saddle)) along the straight line
  from a peak (t = 0) to its saddle (t = 1): falls fast below the summit, flattens near
  the saddle.

The six regions give the same shapes within about 0.1 (bin by bin); the other seven
regions are held out.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["HILLSLOPE", "RIDGE", "hillslope_profile", "ridge_profile", "threshold_profile"]

_U = np.concatenate([[0.0], (np.arange(20) + 0.5) / 20.0, [1.0]])
#: f at u = 0, bin centres 0.025 ... 0.975, 1 (mean of the six regions' medians)
HILLSLOPE = np.array([0.0, 0.0, 0.0, 0.001, 0.007, 0.018, 0.033, 0.056, 0.101, 0.148, 0.211, 0.269, 0.359,
                      0.5, 0.604, 0.708, 0.8, 0.887, 0.993, 1.0, 1.0, 1.0])
_T = np.linspace(0.0, 1.0, 21)
#: g at t = 0, 0.05, ..., 1 (mean of the six regions' medians)
RIDGE = np.array([1.0, 0.985, 0.907, 0.831, 0.744, 0.667, 0.597, 0.542, 0.466, 0.414, 0.342, 0.287, 0.241,
                  0.192, 0.156, 0.108, 0.073, 0.034, 0.011, 0.0, 0.0])


def hillslope_profile(u: NDArray[np.floating]) -> NDArray[np.float64]:
    """Normalised height above the river at relative position ``u`` (0 river, 1 ridge).

    >>> hillslope_profile(np.array([0.0, 0.5, 1.0])).round(3).tolist()
    [0.0, 0.24, 1.0]
    """
    return np.interp(np.clip(u, 0.0, 1.0), _U, HILLSLOPE)


def ridge_profile(t: NDArray[np.floating]) -> NDArray[np.float64]:
    """Normalised height above the saddle at ``t`` along a ridge (0 peak, 1 saddle).

    >>> ridge_profile(np.array([0.0, 0.5, 1.0])).round(3).tolist()
    [1.0, 0.342, 0.0]
    """
    return np.interp(np.clip(t, 0.0, 1.0), _T, RIDGE)


def threshold_profile(u: NDArray[np.floating], convexity: float) -> NDArray[np.float64]:
    """Normalised height ``u + c sin(pi u) / pi`` at ``u`` (0 river, 1 ridge), ``0 <= c <= 1``.

    Gradient ``1 + c cos(pi u)``: ``1 + c`` times the mean at the river (V-shaped valleys), ``1 - c``
    at the ridge (rounded crests), monotone; ``c = 0`` is the paper's linear profile.

    >>> threshold_profile(np.array([0.0, 0.5, 1.0]), 0.5).round(3).tolist()
    [0.0, 0.659, 1.0]
    """
    if not 0.0 <= convexity <= 1.0:
        raise ValueError(f"convexity must be in [0, 1], got {convexity!r}")
    u = np.clip(np.asarray(u, dtype=np.float64), 0.0, 1.0)
    return u + convexity * np.sin(np.pi * u) / np.pi
