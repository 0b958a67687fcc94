"""How well a Divide Tree follows a terrain type: per-feature histogram errors and EMD."""
from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.stats import wasserstein_distance

from orokit.synthesis.terrain_type import FEATURES, TerrainType
from orokit.topology.divide_tree import DivideTree

__all__ = ["tree_feature_values", "compare_to_type", "ridge_statistics"]


def tree_feature_values(tree: DivideTree) -> dict[str, np.ndarray]:
    """Values of every type feature measured on ``tree`` (roots excluded where undefined)."""
    from orokit.synthesis.orometry import tree_orometry

    o = tree_orometry(tree)
    keyed = o["key_saddle"].to_numpy() >= 0
    iso = o["isolation"].to_numpy(float)
    has_iso = np.isfinite(iso)
    return {
        "elevation": tree.peaks["elevation"].to_numpy(float),
        "prominence": o["prominence"].to_numpy(float)[keyed],
        "dominance": o["dominance"].to_numpy(float)[keyed],
        "isolation_distance": iso[has_iso],
        "isolation_direction": o["isolation_direction"].to_numpy(float)[has_iso],
        "saddle_distance": o["saddle_distance"].to_numpy(float)[keyed],
        "saddle_direction": o["saddle_direction"].to_numpy(float)[keyed],
    }


def _merge_pairs(p: np.ndarray) -> np.ndarray:
    if p.size % 2:
        p = np.append(p, 0.0)
    return p.reshape(-1, 2).sum(axis=1)


def compare_to_type(tree: DivideTree, terrain_type: TerrainType) -> pd.DataFrame:
    """Per feature: max histogram-bin error (type bins, and bins merged by two) and EMD.

    Returns a DataFrame indexed by feature with columns ``max_bin_error`` (on the
    type's fine bins), ``max_bin_error_coarse`` (adjacent bins merged in pairs, about
    the 20/12 bins of the classification features), ``emd`` (earth mover's distance
    between the two binned distributions, in the feature's unit; circular features
    use the linear distance on [0, 360)), ``unit`` and ``n``.
    """
    values = tree_feature_values(tree)
    rows = []
    for name, (unit, _) in FEATURES.items():
        h = terrain_type.histograms[name]
        want = h.probabilities()
        got = h.histogram(values[name])
        e = np.asarray(h.edges, float)
        centers = 0.5 * (e[:-1] + e[1:])
        emd = float(wasserstein_distance(centers, centers, want, got)) if got.sum() > 0 else float("nan")
        rows.append({
            "feature": name,
            "max_bin_error": float(np.abs(got - want).max()) if got.sum() > 0 else float("nan"),
            "max_bin_error_coarse": float(np.abs(_merge_pairs(got) - _merge_pairs(want)).max()) if got.sum() > 0 else float("nan"),
            "emd": emd,
            "unit": unit,
            "n": int(np.isfinite(values[name]).sum()),
        })
    return pd.DataFrame(rows).set_index("feature")


def ridge_statistics(tree: DivideTree, quantiles: tuple[float, ...] = (0.5, 0.9, 0.99)) -> dict[str, list[float]]:
    """How steep a tree's relief is, before any rendering (quantiles, unitless m/m).

    ``neighbour_gradient``: ``|h_p - h_q| / d(p, q)`` from every peak p to its nearest peak q
    (the smoothness of the peak elevations); ``half_ridge_slope``: ``(h_end - h_saddle) / d``
    from each end of every ridge to its saddle (what the renderer's ridge profiles and
    flank cones follow); ``ridge_slope``: ``(h_a + h_b - 2 h_saddle) / |AB|``, both drops over
    the ridge's length (the slope at the even split of the ridge); ``higher_end_drop_m`` and
    ``lower_end_drop_m``: each ridge's drop from its higher and its lower end to its saddle (m);
    ``ridge_length_m``: ``|AB|`` (m); ``forced_prominence_m``:
    :func:`orokit.synthesis.saddles.forced_prominence` of the peaks that have a key saddle (m).
    """
    from scipy.spatial import cKDTree

    from orokit.synthesis.saddles import forced_prominence

    x, y, z = (tree.peaks[c].to_numpy(float) for c in ("x", "y", "elevation"))
    a = tree.edges["peak_a"].to_numpy(np.int64)
    b = tree.edges["peak_b"].to_numpy(np.int64)
    s = tree.edges["saddle"].to_numpy(np.int64)
    sx, sy, sz = (tree.saddles[c].to_numpy(float)[s] for c in ("x", "y", "elevation"))
    out: dict[str, np.ndarray] = {}
    if x.size >= 2:
        d, j = cKDTree(np.column_stack([x, y])).query(np.column_stack([x, y]), k=2)
        ok = d[:, 1] > 0
        out["neighbour_gradient"] = np.abs(z - z[j[:, 1]])[ok] / d[ok, 1]
    half = [(z[e] - sz) / np.hypot(x[e] - sx, y[e] - sy) for e in (a, b)]
    h = np.concatenate(half)
    out["half_ridge_slope"] = h[np.isfinite(h)]
    length = np.hypot(x[a] - x[b], y[a] - y[b])
    ok = length > 0
    out["ridge_slope"] = (z[a] + z[b] - 2 * sz)[ok] / length[ok]
    out["higher_end_drop_m"] = np.maximum(z[a], z[b]) - sz
    out["lower_end_drop_m"] = np.minimum(z[a], z[b]) - sz
    out["ridge_length_m"] = length
    forced = forced_prominence(z, a, b)
    out["forced_prominence_m"] = forced[np.isfinite(forced)]
    qs = list(quantiles)
    return {k: [float(v) for v in np.quantile(out[k], qs)] if k in out and out[k].size else [float("nan")] * len(qs)
            for k in ("neighbour_gradient", "half_ridge_slope", "ridge_slope", "higher_end_drop_m",
                      "lower_end_drop_m", "ridge_length_m", "forced_prominence_m")}
