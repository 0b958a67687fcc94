"""Per-peak orometric metrics relative to a domain (a disk of radius R).

These are the per-peak values that the classification histograms (Argudo et al. 2019,
Table 1) are built from. Inputs are peaks already selected inside one disk, with the
disk-independent geometry (key-saddle and isolation distance/direction) precomputed by
:func:`orokit.classify.peaklist.peak_geometry`.

Conventions (orokit)
--------------------
- ``relative_elevation`` defaults to ``(h - min h) / (max h - min h)`` over the disk
  (``"minmax"``, the convention of the paper's published scripts; it ignores the base
  level of the region). ``"max"`` gives the paper's printed ``h / max h``. When all
  peaks have the same elevation, ``"minmax"`` gives 1.
- Distances are clamped at R and divided by R: an isolation larger than R, or unknown
  because nothing higher exists (NaN), counts as R; a missing key saddle (the highest
  peak of a landmass) counts as distance R.
- Directions are degrees counter-clockwise from east in [0, 360), from the peak towards
  the key saddle / isolation target; NaN when the target does not exist (then the peak
  is left out of that direction histogram).
- Dominance ``pi / h`` is clipped to [0, 1]; NaN when ``h <= 0``.
"""
from __future__ import annotations

from typing import Literal

import numpy as np
import pandas as pd

from orokit.errors import InputError

RelativeElevation = Literal["minmax", "max"]
#: convention shared with synthesis: see module docstring
RELATIVE_ELEVATION_DEFAULT: RelativeElevation = "minmax"

#: columns that :func:`disk_metrics` needs
REQUIRED_COLUMNS = (
    "elevation", "prominence", "saddle_distance_m", "saddle_direction_deg",
    "isolation_m", "isolation_direction_deg",
)

#: Jurgalski (2016) dominance group edges
DOMINANCE_GROUP_EDGES = np.array(
    [0.0, 0.0035, 0.007, 0.014, 0.021, 0.042, 0.07, 0.105, 0.14, 0.245, 0.49, 0.882, 1.0]
)


def dominance(elevation: np.ndarray, prominence: np.ndarray) -> np.ndarray:
    """Dominance ``prominence / elevation`` clipped to [0, 1] (NaN where elevation <= 0)."""
    h = np.asarray(elevation, dtype=float)
    p = np.asarray(prominence, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        d = np.where(h > 0, p / np.where(h > 0, h, 1.0), np.nan)
    return np.clip(d, 0.0, 1.0)


def dominance_group(dom: np.ndarray) -> np.ndarray:
    """Index (0..11) of the Jurgalski dominance group of each value; -1 for NaN."""
    d = np.asarray(dom, dtype=float)
    idx = np.searchsorted(DOMINANCE_GROUP_EDGES, np.clip(d, 0, 1), side="right") - 1
    idx = np.minimum(idx, len(DOMINANCE_GROUP_EDGES) - 2)
    return np.where(np.isfinite(d), idx, -1)


def relative_elevation(elevation: np.ndarray, *, convention: RelativeElevation = RELATIVE_ELEVATION_DEFAULT
                       ) -> np.ndarray:
    """Elevation relative to the domain's peaks (see module docstring for conventions)."""
    h = np.asarray(elevation, dtype=float)
    if h.size == 0:
        return h.copy()
    hmax, hmin = np.nanmax(h), np.nanmin(h)
    if convention == "minmax":
        if hmax > hmin:
            return (h - hmin) / (hmax - hmin)
        return np.ones_like(h)
    if convention == "max":
        if hmax > 0:
            return np.clip(h / hmax, 0.0, 1.0)
        return np.full_like(h, np.nan)
    raise InputError(f"relative elevation convention must be 'minmax' or 'max', got {convention!r}")


def relative_prominence(prominence: np.ndarray) -> np.ndarray:
    """``prominence / max prominence`` over the domain (NaN if the maximum is not > 0)."""
    p = np.asarray(prominence, dtype=float)
    if p.size == 0:
        return p.copy()
    pmax = np.nanmax(p)
    if not pmax > 0:
        return np.full_like(p, np.nan)
    return np.clip(p / pmax, 0.0, 1.0)


def axial_resultant(direction_deg: np.ndarray) -> complex:
    """Mean of ``exp(2i theta)`` over the finite directions (0 when there is none).

    Its modulus in [0, 1] is how strongly the directions line up along one axis (1: all
    along one line, either way; 0: no preferred axis); rotating every direction by ``a``
    turns it by ``2a``, so the modulus, and the real part of ``z1 * conj(z2)`` of two such
    means, do not change when the DEM is rotated or flipped.

    Examples
    --------
    >>> round(abs(axial_resultant(np.array([30.0, 210.0, np.nan]))), 6)  # one line, both ways
    1.0
    >>> round(abs(axial_resultant(np.array([0.0, 90.0]))), 6)  # a cross: no axis
    0.0
    """
    t = np.deg2rad(np.asarray(direction_deg, dtype=float))
    t = t[np.isfinite(t)]
    return complex(np.exp(2j * t).mean()) if len(t) else 0j


def clamped_distance(distance_m: np.ndarray, radius_m: float) -> np.ndarray:
    """``min(d, R) / R``; NaN (no target) counts as R, i.e. 1."""
    d = np.asarray(distance_m, dtype=float)
    return np.where(np.isfinite(d), np.minimum(d, radius_m), radius_m) / radius_m


def disk_metrics(peaks: pd.DataFrame, *, radius_m: float,
                 relative_elevation_convention: RelativeElevation = RELATIVE_ELEVATION_DEFAULT) -> pd.DataFrame:
    """Per-peak metrics of the peaks of one disk.

    Parameters
    ----------
    peaks : DataFrame
        Peaks inside the disk with columns :data:`REQUIRED_COLUMNS` (metres, degrees).
    radius_m : float
        Disk radius R in metres (distances are clamped at R).
    relative_elevation_convention : {"minmax", "max"}
        See module docstring.

    Returns
    -------
    DataFrame
        Same index as ``peaks``; columns dominance, dominance_group, relative_elevation,
        relative_prominence, relevance, prominence, isolation_distance,
        isolation_direction, saddle_distance, saddle_direction.

    Examples
    --------
    >>> import pandas as pd
    >>> p = pd.DataFrame({"elevation": [1000.0, 500.0], "prominence": [1000.0, 100.0],
    ...                   "saddle_distance_m": [float("nan"), 2000.0], "saddle_direction_deg": [float("nan"), 90.0],
    ...                   "isolation_m": [float("nan"), 20000.0], "isolation_direction_deg": [float("nan"), 180.0]})
    >>> disk_metrics(p, radius_m=10000.0)[["dominance", "relative_prominence", "saddle_distance"]].values.tolist()
    [[1.0, 1.0, 1.0], [0.2, 0.1, 0.2]]
    """
    missing = [c for c in REQUIRED_COLUMNS if c not in peaks]
    if missing:
        raise InputError(f"peak table lacks columns {missing}; compute them with orokit.classify.peaklist.peak_geometry")
    if not radius_m > 0:
        raise InputError(f"disk radius must be > 0 metres, got {radius_m!r}")
    h = peaks["elevation"].to_numpy(dtype=float)
    p = peaks["prominence"].to_numpy(dtype=float)
    dom = dominance(h, p)
    rel_h = relative_elevation(h, convention=relative_elevation_convention)
    rel_p = relative_prominence(p)
    return pd.DataFrame({
        "dominance": dom,
        "dominance_group": dominance_group(dom),
        "relative_elevation": rel_h,
        "relative_prominence": rel_p,
        "relevance": np.sqrt(rel_p * rel_h),
        "prominence": p,
        "isolation_distance": clamped_distance(peaks["isolation_m"].to_numpy(dtype=float), radius_m),
        "isolation_direction": np.mod(peaks["isolation_direction_deg"].to_numpy(dtype=float), 360.0),
        "saddle_distance": clamped_distance(peaks["saddle_distance_m"].to_numpy(dtype=float), radius_m),
        "saddle_direction": np.mod(peaks["saddle_direction_deg"].to_numpy(dtype=float), 360.0),
    }, index=peaks.index)
