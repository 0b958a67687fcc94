"""Compare two peak lists: location matching, value agreement and parent agreement.

Pure functions on tables with the columns of :data:`orokit.io.peak_lists.PEAK_LIST_COLUMNS`.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from orokit.errors import InputError

__all__ = ["planar_coordinates", "match_peaks", "compare_peak_lists"]


def planar_coordinates(a: pd.DataFrame, b: pd.DataFrame) -> tuple[np.ndarray, np.ndarray, str]:
    """Coordinates of both tables in one planar frame: ``"cells"`` (row, col) when both have
    them, else ``"m"`` (lat/lon on a local equirectangular frame, or x/y)."""
    def has(t, cols):
        return len(t) == 0 or np.isfinite(t[list(cols)].to_numpy(float)).all()

    if has(a, ("row", "col")) and has(b, ("row", "col")):
        return a[["row", "col"]].to_numpy(float), b[["row", "col"]].to_numpy(float), "cells"
    if has(a, ("lat", "lon")) and has(b, ("lat", "lon")):
        lat0 = np.radians(np.nanmean(np.concatenate([a["lat"], b["lat"]])) if len(a) + len(b) else 0.0)
        r = 6_371_008.8
        def f(t):
            return np.column_stack([np.radians(t["lat"].to_numpy(float)) * r,
                                    np.radians(t["lon"].to_numpy(float)) * r * np.cos(lat0)])
        return f(a), f(b), "m"
    if has(a, ("x", "y")) and has(b, ("x", "y")):
        return a[["y", "x"]].to_numpy(float), b[["y", "x"]].to_numpy(float), "m"
    raise InputError("the two peak lists share no coordinates (raster row/col, lat/lon or x/y)")


def match_peaks(pa: np.ndarray, pb: np.ndarray, max_distance: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One-to-one matching of points within ``max_distance``, closest pairs first.

    Returns ``(ia, ib, dist)`` of the matched pairs.
    """
    from scipy.spatial import cKDTree

    if len(pa) == 0 or len(pb) == 0:
        e = np.empty(0, np.int64)
        return e, e, np.empty(0)
    pairs = cKDTree(pa).sparse_distance_matrix(cKDTree(pb), max_distance, output_type="ndarray")
    order = np.lexsort((pairs["j"], pairs["i"], pairs["v"]))
    used_a = np.zeros(len(pa), bool)
    used_b = np.zeros(len(pb), bool)
    ia, ib, dd = [], [], []
    for k in order:
        i, j = int(pairs["i"][k]), int(pairs["j"][k])
        if not used_a[i] and not used_b[j]:
            used_a[i] = used_b[j] = True
            ia.append(i)
            ib.append(j)
            dd.append(float(pairs["v"][k]))
    return np.array(ia, np.int64), np.array(ib, np.int64), np.array(dd)


def compare_peak_lists(a: pd.DataFrame, b: pd.DataFrame, *, max_cells: float = 1.0, max_distance_m: float = 100.0,
                       z_tolerance_m: float = 0.01) -> tuple[dict, pd.DataFrame]:
    """Compare peak list ``a`` (under test) with ``b`` (reference).

    Peaks are matched one to one within ``max_cells`` (both lists on one raster grid)
    or ``max_distance_m``. Reported: location precision (matched / len(a)) and recall
    (matched / len(b)); the share of matched pairs whose elevation and prominence agree
    within ``z_tolerance_m``; value precision/recall of the (elevation, prominence)
    pairs regardless of location (multiset); and, where both lists have parents, the
    share of matched peaks whose line (prominence) parent is the matched partner of the
    other's.

    Returns ``(summary, pairs)``: a dict of the figures and a table with one row per
    matched pair and per unmatched peak (``a``, ``b``: row positions, -1 for none).
    """
    pa, pb, unit = planar_coordinates(a, b)
    radius = max_cells if unit == "cells" else max_distance_m
    ia, ib, dist = match_peaks(pa, pb, radius)
    na, nb, m = len(a), len(b), len(ia)
    za, zb = a["elevation"].to_numpy(float), b["elevation"].to_numpy(float)
    qa, qb = a["prominence"].to_numpy(float), b["prominence"].to_numpy(float)
    dz, dq = za[ia] - zb[ib], qa[ia] - qb[ib]
    agree = (np.abs(dz) <= z_tolerance_m) & (np.abs(dq) <= z_tolerance_m)
    # values regardless of location: multiset of rounded (elevation, prominence)
    step = max(z_tolerance_m, 1e-9)
    va = pd.Series(list(zip(np.round(za / step).astype(np.int64), np.round(qa / step).astype(np.int64))))
    vb = pd.Series(list(zip(np.round(zb / step).astype(np.int64), np.round(qb / step).astype(np.int64))))
    common = int((pd.concat([va.value_counts(), vb.value_counts()], axis=1).fillna(0).min(axis=1)).sum())
    summary = {
        "peaks_a": na, "peaks_b": nb, "matched": m, "match_radius": float(radius), "match_unit": unit,
        "location_precision": m / na if na else float("nan"), "location_recall": m / nb if nb else float("nan"),
        "matched_values_agree": float(agree.mean()) if m else float("nan"),
        "value_precision": common / na if na else float("nan"), "value_recall": common / nb if nb else float("nan"),
        "median_abs_prominence_diff": float(np.median(np.abs(dq))) if m else float("nan"),
        "max_abs_prominence_diff": float(np.max(np.abs(dq))) if m else float("nan"),
    }
    to_b = np.full(na, -1, np.int64)
    to_b[ia] = ib
    for what in ("line_parent", "prominence_parent"):
        fa, fb = a[what].to_numpy(np.int64)[ia], b[what].to_numpy(np.int64)[ib]
        both = (fa >= 0) & (fb >= 0)
        summary[f"{what}_compared"] = int(both.sum())
        summary[f"{what}_agree"] = float((to_b[fa[both]] == fb[both]).mean()) if both.any() else float("nan")
    un_a = np.setdiff1d(np.arange(na), ia)
    un_b = np.setdiff1d(np.arange(nb), ib)
    pairs = pd.DataFrame({
        "a": np.concatenate([ia, un_a, np.full(un_b.size, -1)]).astype(np.int64),
        "b": np.concatenate([ib, np.full(un_a.size, -1), un_b]).astype(np.int64),
        "distance": np.concatenate([dist, np.full(un_a.size + un_b.size, np.nan)]),
        "elevation_a": np.concatenate([za[ia], za[un_a], np.full(un_b.size, np.nan)]),
        "elevation_b": np.concatenate([zb[ib], np.full(un_a.size, np.nan), zb[un_b]]),
        "prominence_a": np.concatenate([qa[ia], qa[un_a], np.full(un_b.size, np.nan)]),
        "prominence_b": np.concatenate([qb[ib], np.full(un_a.size, np.nan), qb[un_b]]),
    })
    pairs["status"] = np.where(pairs["a"] < 0, "missing", np.where(pairs["b"] < 0, "extra", "matched"))
    return summary, pairs
