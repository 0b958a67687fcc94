"""How well a Divide Tree follows a terrain type: per-feature histogram errors and EMD."""
from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.stats import wasserstein_distance

from orokit.synthesis.terrain_type import FEATURES, TerrainType
from orokit.topology.divide_tree import DivideTree

__all__ = ["tree_feature_values", "compare_to_type"]


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
