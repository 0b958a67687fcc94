"""Orometric histogram specification and per-disk histograms (Argudo et al. 2019, Table 1).

A :class:`HistogramSpec` fixes, for every feature, the bin edges and whether the last
bin is open (values above the last edge are counted in it). It is saved with every
trained model so features computed later use exactly the same bins.
"""
from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd

from orokit.errors import SchemaError

#: Jurgalski (2016) dominance groups, as used by the paper (12 bins).
DOMINANCE_GROUP_EDGES: tuple[float, ...] = (
    0.0, 0.0035, 0.007, 0.014, 0.021, 0.042, 0.07, 0.105, 0.14, 0.245, 0.49, 0.882, 1.0,
)

#: feature name -> per-peak metric column of :func:`orokit.metrics.disk.disk_metrics`
FEATURE_METRIC: dict[str, str] = {
    "dominance": "dominance",
    "dominance_groups": "dominance",
    "relative_elevation": "relative_elevation",
    "isolation_direction": "isolation_direction",
    "isolation_distance": "isolation_distance",
    "saddle_direction": "saddle_direction",
    "saddle_distance": "saddle_distance",
    "prominence": "prominence",
    "relative_prominence": "relative_prominence",
    "relevance": "relevance",
}

#: human-readable names (Table 2 rows)
FEATURE_TITLES: dict[str, str] = {
    "dominance": "Dominance",
    "dominance_groups": "Dominance groups",
    "relative_elevation": "Normalized elevation",
    "isolation_direction": "Isolation direction",
    "isolation_distance": "Isolation distance",
    "saddle_direction": "Key saddle direction",
    "saddle_distance": "Key saddle distance",
    "prominence": "Prominence",
    "relative_prominence": "Relative prominence",
    "relevance": "Relevance",
}


@dataclasses.dataclass(frozen=True)
class FeatureBins:
    """Bins of one histogram feature.

    Parameters
    ----------
    name : str
        Feature name; its columns are ``<name>_<bin>``.
    edges : tuple of float
        Increasing bin edges (``len(edges) - 1`` bins).
    open_last : bool
        Count values above the last edge in the last bin (prominence in metres).
    """

    name: str
    edges: tuple[float, ...]
    open_last: bool = False

    def __post_init__(self) -> None:
        e = np.asarray(self.edges, dtype=float)
        if e.ndim != 1 or e.size < 2 or not np.all(np.diff(e) > 0):
            raise SchemaError(
                f"bin edges of feature {self.name!r} must be >= 2 strictly increasing numbers, got {self.edges!r}"
            )

    @property
    def n_bins(self) -> int:
        return len(self.edges) - 1

    @property
    def columns(self) -> list[str]:
        return [f"{self.name}_{i}" for i in range(self.n_bins)]

    def counts(self, values: np.ndarray) -> np.ndarray:
        """Bin counts of ``values`` (NaN ignored; values outside the range are clipped
        into the end bins only when ``open_last`` (upper end) or at the lower edge)."""
        v = np.asarray(values, dtype=float)
        v = v[np.isfinite(v)]
        e = np.asarray(self.edges, dtype=float)
        if self.open_last:
            v = np.minimum(v, e[-1])
        # inclusive upper edge: the maximum (e.g. relative value 1.0) falls in the last bin
        v = np.clip(v, e[0], e[-1])
        idx = np.searchsorted(e, v, side="right") - 1
        idx = np.minimum(idx, self.n_bins - 1)
        return np.bincount(idx, minlength=self.n_bins).astype(np.int64)


def _uniform(name: str, lo: float, hi: float, n: int, open_last: bool = False) -> FeatureBins:
    return FeatureBins(name, tuple(float(v) for v in np.linspace(lo, hi, n + 1)), open_last)


@dataclasses.dataclass(frozen=True)
class HistogramSpec:
    """Ordered set of histogram features (one feature vector = their concatenation).

    Examples
    --------
    >>> spec = HistogramSpec.paper()
    >>> len(spec.columns)
    176
    >>> spec.columns[:2]
    ['dominance_0', 'dominance_1']
    """

    features: tuple[FeatureBins, ...]

    @classmethod
    def paper(cls) -> HistogramSpec:
        """The bins of Argudo et al. (2019), Table 1 (angles in degrees, distances / R)."""
        return cls((
            _uniform("dominance", 0, 1, 20),
            FeatureBins("dominance_groups", DOMINANCE_GROUP_EDGES),
            _uniform("relative_elevation", 0, 1, 20),
            _uniform("isolation_direction", 0, 360, 12),
            _uniform("isolation_distance", 0, 1, 20),
            _uniform("saddle_direction", 0, 360, 12),
            _uniform("saddle_distance", 0, 1, 20),
            _uniform("prominence", 0, 2000, 20, open_last=True),
            _uniform("relative_prominence", 0, 1, 20),
            _uniform("relevance", 0, 1, 20),
        ))

    @property
    def names(self) -> list[str]:
        return [f.name for f in self.features]

    @property
    def columns(self) -> list[str]:
        return [c for f in self.features for c in f.columns]

    def groups(self) -> dict[str, list[str]]:
        """Feature name -> its column names."""
        return {f.name: f.columns for f in self.features}

    def to_dict(self) -> dict[str, Any]:
        return {"features": [
            {"name": f.name, "edges": list(f.edges), "open_last": f.open_last} for f in self.features
        ]}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> HistogramSpec:
        try:
            return cls(tuple(
                FeatureBins(str(f["name"]), tuple(float(e) for e in f["edges"]), bool(f.get("open_last", False)))
                for f in d["features"]
            ))
        except (KeyError, TypeError) as exc:
            raise SchemaError(f"not a HistogramSpec dictionary ({exc!r}): {str(d)[:200]}") from exc

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), sort_keys=True)

    def select(self, names: Sequence[str]) -> HistogramSpec:
        """A spec with only the named features (in the given order)."""
        by = {f.name: f for f in self.features}
        missing = [n for n in names if n not in by]
        if missing:
            raise SchemaError(f"unknown histogram features {missing}; available: {sorted(by)}")
        return HistogramSpec(tuple(by[n] for n in names))


def disk_histograms(metrics: pd.DataFrame, spec: HistogramSpec | None = None, *,
                    normalize: bool = True) -> pd.Series:
    """Concatenated histograms of the per-peak metrics of one disk.

    Parameters
    ----------
    metrics : DataFrame
        One row per peak, columns from :func:`orokit.metrics.disk.disk_metrics`.
    spec : HistogramSpec, optional
        Bins; default :meth:`HistogramSpec.paper`.
    normalize : bool
        Divide each feature's counts by its number of finite values (sum 1), as the
        paper does. A feature with no finite value gives an all-zero histogram.

    Returns
    -------
    Series
        Indexed by ``spec.columns``.

    Notes
    -----
    Direction features are NaN for peaks without a key saddle (the highest peak) or
    without an isolation target; those peaks are left out of that feature's histogram,
    so its counts sum to the number of peaks that have the direction.
    """
    spec = spec or HistogramSpec.paper()
    parts = []
    for fb in spec.features:
        col = FEATURE_METRIC.get(fb.name, fb.name)
        if col not in metrics:
            raise SchemaError(f"per-peak metrics lack column {col!r} needed by feature {fb.name!r}")
        c = fb.counts(metrics[col].to_numpy(dtype=float)).astype(float)
        if normalize:
            total = c.sum()
            c = c / total if total > 0 else c
        parts.append(c)
    return pd.Series(np.concatenate(parts) if parts else np.zeros(0), index=spec.columns)
