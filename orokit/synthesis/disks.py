"""Per-disk statistics of a peak set: what a 10 km neighbourhood holds (issue 11).

The region classifier describes ground by disks of radius R (10 km): how many peaks a
disk holds, how prominent and how high its highest peaks are. Matching a region's
global histograms does not fix how those quantities vary from disk to disk, so a
terrain type also records their distribution over disk centres on a regular grid
inside the data (every disk entirely inside it), and the dart throwing follows one of
them (:func:`coverage_targets`).

``top_rank`` of a disk is the share of all the peaks that are higher than the disk's
highest peak: 0 for a disk holding the highest peak, small when every disk holds one
of the high peaks. It does not depend on the elevation scale, so it survives edits
of the elevation histogram. ``median_rank`` of a disk is the median elevation rank
``(i + 0.5) / n`` of the peaks it holds: how low the lowest 10 km neighbourhoods lie among the
region's peaks (its low quantiles; a twin whose lowest peaks gather in one wide basin has
disks far lower than any real one, which the classifier reads as another region). ``peak_relief_m`` of a
disk is the spread of its peaks' elevations (90th minus 10th percentile, metres): a twin whose every disk
reaches down into a valley has more of it than the source's disks.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from orokit.errors import SchemaError

__all__ = ["DISK_RADIUS_M", "DISK_LEVELS", "BORDER_BANDS", "disk_centres", "disk_statistics", "disk_quantiles",
           "level_quantiles",
           "check_disk_quantiles", "coverage_targets", "border_distance", "border_rank", "border_density", "shrink_border_density",
           "band_areas", "interior_share"]

#: radius of the disks (the region classifier's R)
DISK_RADIUS_M = 10_000.0
#: quantile levels recorded in a terrain type
DISK_LEVELS = tuple(float(v) for v in np.linspace(0.0, 1.0, 21))
#: recorded quantities (per disk)
DISK_QUANTITIES = ("peaks", "max_prominence_m", "top_rank")
#: at most this many disk centres (the grid step grows to stay below it)
MAX_CENTRES = 4096
#: bands of the normalised distance to the data border (:func:`border_distance`): five
#: bands of equal area on a square, the outermost first
BORDER_BANDS = (0.0, 0.106, 0.225, 0.368, 0.553, 1.0)


def disk_centres(extent: tuple[float, float, float, float], radius_m: float = DISK_RADIUS_M,
                 step_m: float | None = None) -> tuple[np.ndarray, np.ndarray, float]:
    """Centres (x, y) of the disks of ``radius_m`` lying entirely inside ``extent``.

    ``extent`` is ``(xmin, ymin, xmax, ymax)`` in metres. The centres form a regular grid
    of step ``step_m`` (default ``radius_m / 10``, enlarged to keep at most
    :data:`MAX_CENTRES`); empty when the extent is narrower than ``2 radius_m``.
    Returns x, y (flattened, row-major from the south-west) and the step used.
    """
    xmin, ymin, xmax, ymax = (float(v) for v in extent)
    w, h = xmax - xmin - 2 * radius_m, ymax - ymin - 2 * radius_m
    step = float(step_m) if step_m is not None else radius_m / 10.0
    if w < 0 or h < 0:
        return np.empty(0), np.empty(0), step
    while (math.floor(w / step) + 1) * (math.floor(h / step) + 1) > MAX_CENTRES:
        step *= 1.25
    gx = xmin + radius_m + np.arange(math.floor(w / step) + 1) * step
    gy = ymin + radius_m + np.arange(math.floor(h / step) + 1) * step
    cx, cy = np.meshgrid(gx, gy)
    return cx.ravel(), cy.ravel(), step


def disk_statistics(x: np.ndarray, y: np.ndarray, elevation: np.ndarray, prominence: np.ndarray,
                    extent: tuple[float, float, float, float], *, radius_m: float = DISK_RADIUS_M,
                    min_prominence_m: float = 30.0, step_m: float | None = None) -> dict[str, np.ndarray]:
    """Per-disk peak count, maximum prominence, ``top_rank``, ``median_rank`` and ``peak_relief_m`` (see the
    module docstring).

    Only peaks with prominence >= ``min_prominence_m`` count (x, y in metres of a planar
    frame). Disks with no peak have ``max_prominence_m`` 0, ``top_rank`` 1 and ``median_rank`` and
    ``peak_relief_m`` NaN.

    Examples
    --------
    >>> import numpy as np
    >>> s = disk_statistics(np.array([15e3, 40e3]), np.array([15e3, 15e3]), np.array([900., 500.]),
    ...                     np.array([800., 100.]), (0, 0, 50e3, 30e3), step_m=5e3)
    >>> s["peaks"].tolist()[:7], s["top_rank"].tolist()[:7], s["median_rank"].tolist()[:2]
    ([1, 1, 1, 0, 0, 1, 1], [0.0, 0.0, 0.0, 1.0, 1.0, 0.5, 0.5], [0.75, 0.75])
    >>> s["peak_relief_m"].tolist()[:2]
    [0.0, 0.0]
    """
    x, y = np.asarray(x, float), np.asarray(y, float)
    z, prom = np.asarray(elevation, float), np.asarray(prominence, float)
    keep = np.isfinite(x) & np.isfinite(y) & (prom >= min_prominence_m)
    x, y, z, prom = x[keep], y[keep], z[keep], prom[keep]
    cx, cy, _ = disk_centres(extent, radius_m, step_m)
    n = np.zeros(cx.size, np.int64)
    mp = np.zeros(cx.size)
    top = np.ones(cx.size)
    med = np.full(cx.size, np.nan)
    rel = np.full(cx.size, np.nan)
    if x.size and cx.size:
        # rank of every peak: share of the peaks strictly higher than it; mid-point rank in increasing elevation
        zs = np.sort(z)
        higher = (z.size - np.searchsorted(zs, z, side="right")) / z.size
        rank = (np.argsort(np.argsort(z, kind="stable"), kind="stable") + 0.5) / z.size
        for i, members in enumerate(cKDTree(np.c_[x, y]).query_ball_point(np.c_[cx, cy], radius_m)):
            if members:
                n[i] = len(members)
                mp[i] = prom[members].max()
                top[i] = higher[members].min()
                med[i] = np.median(rank[members])
                lo, hi = np.quantile(z[members], (0.1, 0.9))
                rel[i] = hi - lo
    return {"x": cx, "y": cy, "peaks": n, "max_prominence_m": mp, "top_rank": top, "median_rank": med,
            "peak_relief_m": rel}


def level_quantiles(values: np.ndarray) -> list[float] | None:
    """Quantiles at :data:`DISK_LEVELS` of a per-disk quantity (``median_rank``, ``peak_relief_m``; empty disks,
    NaN, left out; None without any)."""
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    return [float(q) for q in np.quantile(v, np.asarray(DISK_LEVELS))] if v.size else None


def border_distance(x: np.ndarray, y: np.ndarray, extent: tuple[float, float, float, float]) -> np.ndarray:
    """Distance to the nearest side of ``extent``, divided by half its shorter side (0 on the border, 1 at the centre of a square).

    >>> border_distance(np.array([0.0, 25.0, 50.0]), np.array([50.0, 50.0, 50.0]), (0, 0, 100, 100)).tolist()
    [0.0, 0.5, 1.0]
    """
    xmin, ymin, xmax, ymax = (float(v) for v in extent)
    half = 0.5 * min(xmax - xmin, ymax - ymin)
    d = np.minimum.reduce([np.asarray(x, float) - xmin, xmax - np.asarray(x, float),
                           np.asarray(y, float) - ymin, ymax - np.asarray(y, float)])
    return np.clip(d / half, 0.0, 1.0) if half > 0 else np.zeros(np.shape(d))


def border_rank(x: np.ndarray, y: np.ndarray, elevation: np.ndarray,
                extent: tuple[float, float, float, float]) -> list[float]:
    """Mean elevation rank of the peaks in each :data:`BORDER_BANDS` band (outermost first).

    The rank of a peak is ``(i + 0.5) / n`` in increasing elevation, so peaks placed
    irrespective of the border give 0.5 in every band; a crop centred on a massif gives
    ranks rising towards the centre. An empty band gets 0.5.

    >>> x = np.array([1.0, 2.0, 50.0, 48.0]); y = np.array([1.0, 98.0, 50.0, 52.0])
    >>> border_rank(x, y, np.array([100.0, 200.0, 900.0, 800.0]), (0, 0, 100, 100))
    [0.25, 0.5, 0.5, 0.5, 0.75]
    """
    z = np.asarray(elevation, float)
    if z.size == 0:
        return [0.5] * (len(BORDER_BANDS) - 1)
    rank = (np.argsort(np.argsort(z, kind="stable"), kind="stable") + 0.5) / z.size
    band = np.clip(np.searchsorted(BORDER_BANDS, border_distance(x, y, extent), side="right") - 1,
                   0, len(BORDER_BANDS) - 2)
    total = np.bincount(band, weights=rank, minlength=len(BORDER_BANDS) - 1)
    count = np.bincount(band, minlength=len(BORDER_BANDS) - 1)
    return [float(t / c) if c else 0.5 for t, c in zip(total, count)]


def band_areas(extent: tuple[float, float, float, float]) -> np.ndarray:
    """Area of each :data:`BORDER_BANDS` band of ``extent`` (outermost first), exactly.

    The cells at normalised border distance >= t form a rectangle of
    ``(w - 2 t h) x (hgt - 2 t h)``, h half the shorter side.

    >>> band_areas((0, 0, 100, 100)).round(0).tolist()
    [2008.0, 1986.0, 2012.0, 1996.0, 1998.0]
    """
    xmin, ymin, xmax, ymax = (float(v) for v in extent)
    w, hgt = xmax - xmin, ymax - ymin
    half = 0.5 * min(w, hgt)
    t = np.asarray(BORDER_BANDS)
    inner = np.clip(w - 2 * t * half, 0.0, None) * np.clip(hgt - 2 * t * half, 0.0, None)
    return inner[:-1] - inner[1:]


def border_density(x: np.ndarray, y: np.ndarray, extent: tuple[float, float, float, float]) -> list[float]:
    """Peak density in each :data:`BORDER_BANDS` band (outermost first) over the mean density of ``extent``.

    1 in every band for peaks spread irrespective of the border; a crop centred on a
    massif gives more than 1 in the middle. No peak: 1 everywhere.

    >>> [round(v, 2) for v in border_density(np.array([1.0, 2.0, 50.0, 48.0]), np.array([1.0, 98.0, 50.0, 52.0]),
    ...                                       (0, 0, 100, 100))]
    [2.49, 0.0, 0.0, 0.0, 2.5]
    """
    x, y = np.asarray(x, float), np.asarray(y, float)
    area = band_areas(extent)
    if x.size == 0 or area.sum() <= 0:
        return [1.0] * (len(BORDER_BANDS) - 1)
    band = np.clip(np.searchsorted(BORDER_BANDS, border_distance(x, y, extent), side="right") - 1,
                   0, len(BORDER_BANDS) - 2)
    count = np.bincount(band, minlength=len(BORDER_BANDS) - 1)
    mean = x.size / area.sum()
    return [float(c / (a * mean)) if a > 0 else 1.0 for c, a in zip(count, area)]


def shrink_border_density(profile: Sequence[float], n_peaks: int) -> list[float]:
    """``profile`` (a :func:`border_density` of ``n_peaks`` peaks) shrunk towards 1 by its sampling noise.

    A band holds about ``n_peaks / 5`` peaks, so its relative density has a Poisson variance of about
    ``5 v / n_peaks`` (v the band's value). The deviations from 1 are multiplied by the positive-part
    James-Stein factor ``max(0, 1 - mean variance / mean squared deviation)``: a profile within its
    noise becomes flat, a large tree's profile stays nearly as measured (issue 11, session 16).

    >>> [round(v, 2) for v in shrink_border_density([1.34, 0.54, 1.13, 1.18, 0.81], 149)]
    [1.2, 0.73, 1.08, 1.11, 0.89]
    >>> shrink_border_density([1.1, 0.9, 1.0, 1.0, 1.0], 100)
    [1.0, 1.0, 1.0, 1.0, 1.0]
    """
    b = np.asarray(profile, float)
    if b.size == 0 or n_peaks <= 0:
        return [1.0] * b.size
    dev = b - 1.0
    spread = float(np.mean(dev * dev))
    noise = float(np.mean(b.size * np.maximum(b, 0.0) / float(n_peaks)))
    k = max(0.0, 1.0 - noise / spread) if spread > 0 else 0.0
    return [float(v) for v in 1.0 + k * dev]


def interior_share(x: np.ndarray, y: np.ndarray, elevation: np.ndarray, extent: tuple[float, float, float, float],
                   *, top: float = 0.02, margin_m: float = DISK_RADIUS_M) -> float:
    """Share of the highest ``top`` of the peaks (at least one) lying at least ``margin_m`` inside ``extent``.

    With peaks placed irrespective of the border it is near the interior's share of the
    area; the real DEMs, cropped around their relief, hold more of their highest peaks inside.

    >>> interior_share(np.array([50.0, 5.0, 60.0]), np.array([50.0, 50.0, 40.0]), np.array([3.0, 2.0, 1.0]),
    ...                (0, 0, 100, 100), top=0.5, margin_m=10)
    0.5
    """
    z = np.asarray(elevation, float)
    if z.size == 0:
        return float("nan")
    order = np.argsort(-z, kind="stable")[: max(1, int(round(top * z.size)))]
    xmin, ymin, xmax, ymax = (float(v) for v in extent)
    px, py = np.asarray(x, float)[order], np.asarray(y, float)[order]
    inside = (px - xmin >= margin_m) & (xmax - px >= margin_m) & (py - ymin >= margin_m) & (ymax - py >= margin_m)
    return float(inside.mean())


def disk_quantiles(stats: Mapping[str, np.ndarray], *, radius_m: float = DISK_RADIUS_M) -> dict[str, Any] | None:
    """The terrain type's record of :func:`disk_statistics`: quantiles at :data:`DISK_LEVELS`.

    None when there is no disk (data narrower than ``2 radius_m``).
    """
    if len(stats["peaks"]) == 0:
        return None
    levels = np.asarray(DISK_LEVELS)
    out: dict[str, Any] = {"radius_m": float(radius_m), "n_disks": int(len(stats["peaks"])),
                           "levels": [float(v) for v in levels]}
    for k in DISK_QUANTITIES:
        out[k] = [float(v) for v in np.quantile(np.asarray(stats[k], float), levels)]
    return out


def check_disk_quantiles(disks: Mapping[str, Any]) -> dict[str, Any]:
    """Validate a terrain type's ``disks`` record; returns it with floats."""
    try:
        levels = [float(v) for v in disks["levels"]]
        out: dict[str, Any] = {"radius_m": float(disks["radius_m"]), "n_disks": int(disks.get("n_disks", 0)),
                               "levels": levels}
        for k in DISK_QUANTITIES:
            out[k] = [float(v) for v in disks[k]]
    except (KeyError, TypeError, ValueError) as exc:
        raise SchemaError(f"terrain type disks record needs radius_m, levels and {list(DISK_QUANTITIES)} "
                          f"(lists of numbers): {type(exc).__name__}: {exc}") from exc
    lv = np.asarray(levels)
    if not (out["radius_m"] > 0 and lv.size >= 2 and lv[0] == 0.0 and lv[-1] == 1.0 and np.all(np.diff(lv) > 0)):
        raise SchemaError(f"terrain type disks record: radius_m must be > 0 and levels increase from 0 to 1, "
                          f"got radius_m={out['radius_m']!r}, levels={levels[:4]}...")
    for k in DISK_QUANTITIES:
        v = np.asarray(out[k])
        if v.size != lv.size or not np.all(np.isfinite(v)) or np.any(np.diff(v) < 0):
            raise SchemaError(f"terrain type disks record: {k} needs {lv.size} finite non-decreasing quantiles")
    if out["top_rank"][0] < 0 or out["top_rank"][-1] > 1:
        raise SchemaError("terrain type disks record: top_rank quantiles must lie in [0, 1]")
    if disks.get("border_rank") is not None:  # optional: types made before session 5 lack it
        try:
            br = [float(v) for v in disks["border_rank"]]
        except (TypeError, ValueError) as exc:
            raise SchemaError(f"terrain type disks record: border_rank must be a list of numbers ({exc})") from exc
        if len(br) != len(BORDER_BANDS) - 1 or not all(0.0 <= v <= 1.0 for v in br):
            raise SchemaError(f"terrain type disks record: border_rank needs {len(BORDER_BANDS) - 1} mean ranks "
                              f"in [0, 1] (one per border band), got {disks['border_rank']!r}")
        out["border_rank"] = br
    if disks.get("border_density") is not None:  # optional: types made before session 15 lack it
        try:
            bd = [float(v) for v in disks["border_density"]]
        except (TypeError, ValueError) as exc:
            raise SchemaError(f"terrain type disks record: border_density must be a list of numbers ({exc})") from exc
        if len(bd) != len(BORDER_BANDS) - 1 or not all(0.0 <= v < math.inf for v in bd) or not any(bd):
            raise SchemaError(f"terrain type disks record: border_density needs {len(BORDER_BANDS) - 1} relative "
                              f"densities >= 0, not all 0 (one per border band), got {disks['border_density']!r}")
        out["border_density"] = bd
    if disks.get("median_rank") is not None:  # optional: types made before session 18 lack it
        try:
            mr = [float(v) for v in disks["median_rank"]]
        except (TypeError, ValueError) as exc:
            raise SchemaError(f"terrain type disks record: median_rank must be a list of numbers ({exc})") from exc
        if len(mr) != lv.size or not all(0.0 <= v <= 1.0 for v in mr) or np.any(np.diff(mr) < 0):
            raise SchemaError(f"terrain type disks record: median_rank needs {lv.size} non-decreasing quantiles "
                              f"in [0, 1] (one per level), got {disks['median_rank']!r}")
        out["median_rank"] = mr
    if disks.get("peak_relief_m") is not None:  # optional: types made before session 19 lack it
        try:
            pr = [float(v) for v in disks["peak_relief_m"]]
        except (TypeError, ValueError) as exc:
            raise SchemaError(f"terrain type disks record: peak_relief_m must be a list of numbers ({exc})") from exc
        if len(pr) != lv.size or not all(0.0 <= v < math.inf for v in pr) or np.any(np.diff(pr) < 0):
            raise SchemaError(f"terrain type disks record: peak_relief_m needs {lv.size} non-decreasing quantiles "
                              f">= 0 in metres (one per level), got {disks['peak_relief_m']!r}")
        out["peak_relief_m"] = pr
    return out


def coverage_targets(disks: Mapping[str, Any], n: int) -> np.ndarray:
    """Share of disk centres that should hold one of the ``k + 1`` highest peaks, for k < n.

    A disk holds one of the ``k + 1`` highest of ``n`` peaks exactly when its ``top_rank``
    is at most ``k / n``; the type's quantiles of ``top_rank`` give that share.
    """
    levels = np.asarray(disks["levels"], float)
    tr = np.asarray(disks["top_rank"], float)
    r = (np.arange(int(n)) + 0.5) / max(int(n), 1)
    # the CDF of top_rank at r (the quantile function inverted; peak k has top_rank k / n)
    return np.interp(r, tr, levels, left=0.0, right=1.0)
