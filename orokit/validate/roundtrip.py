"""Round trip: re-analyse a rendered raster and compare its orometry with the Divide Tree.

Paper §7.1: the terrain made from a Divide Tree must carry the tree's orometry (peaks at
their places with their prominences), follow the terrain type's histograms, and be
recognised as its region by the classifier trained on real terrain.
"""
from __future__ import annotations

import json
import logging
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd
from scipy.spatial import cKDTree

from orokit.errors import InputError

logger = logging.getLogger(__name__)

__all__ = ["PeakComparison", "RoundTrip", "compare_peaks", "model_feature_options", "roundtrip", "roundtrip_table"]


@dataclass
class PeakComparison:
    """Tree peaks (prominence >= eps) matched to raster peaks.

    ``peaks``: one row per tree peak with ``x, y, prominence, matched (raster peak id or
    -1), distance_m, raster_prominence, recovered``; ``extra``: raster peaks >= eps with
    no tree peak within the distance tolerance.
    """

    peaks: pd.DataFrame
    extra: pd.DataFrame
    distance_tol_m: float
    prominence_tol: tuple[float, float]

    @property
    def n_tree(self) -> int:
        return int(len(self.peaks))

    @property
    def recovered_share(self) -> float:
        return float(self.peaks["recovered"].mean()) if len(self.peaks) else float("nan")

    @property
    def extra_share(self) -> float:
        return float(len(self.extra) / max(len(self.peaks), 1))

    def summary(self) -> dict[str, Any]:
        d = self.peaks["raster_prominence"] - self.peaks["prominence"]
        return {
            "tree_peaks": self.n_tree,
            "recovered": int(self.peaks["recovered"].sum()),
            "recovered_share": self.recovered_share,
            "extra_peaks": int(len(self.extra)),
            "extra_share": self.extra_share,
            "median_abs_prominence_error_m": float(np.nanmedian(np.abs(d))) if np.isfinite(d).any() else float("nan"),
            "distance_tol_m": self.distance_tol_m,
            "prominence_tol_abs_m": self.prominence_tol[0],
            "prominence_tol_rel": self.prominence_tol[1],
        }


def compare_peaks(
    tree,
    raster_peaks: pd.DataFrame,
    *,
    min_prominence_m: float = 30.0,
    distance_tol_m: float = 200.0,
    prominence_tol_m: float = 15.0,
    prominence_tol_rel: float = 0.1,
) -> PeakComparison:
    """Match the tree's peaks (prominence >= eps) with the raster's peaks.

    A tree peak is *recovered* when a raster peak lies within ``distance_tol_m`` and its
    prominence differs by at most ``max(prominence_tol_m, prominence_tol_rel * prominence)``.
    Raster peaks >= eps with no tree peak (any prominence) within ``distance_tol_m`` are
    *extra*. Matching takes the nearest raster peak (any prominence).
    """
    if distance_tol_m <= 0 or not math.isfinite(distance_tol_m):
        raise InputError(f"distance_tol_m must be a positive number of metres, got {distance_tol_m!r}")
    prom = tree.prominence_table()["prominence"].to_numpy(float)
    tp = tree.peaks[["x", "y"]].to_numpy(float)
    keep = prom >= min_prominence_m
    rp = raster_peaks[["x", "y"]].to_numpy(float)
    rprom = raster_peaks["prominence"].to_numpy(float)
    rows = pd.DataFrame({"x": tp[keep, 0], "y": tp[keep, 1], "prominence": prom[keep]},
                        index=pd.Index(np.flatnonzero(keep), name="tree_peak"))
    if len(rp):
        dist, idx = cKDTree(rp).query(tp[keep])
        ok = dist <= distance_tol_m
        rows["matched"] = np.where(ok, raster_peaks.index.to_numpy()[np.minimum(idx, len(rp) - 1)], -1)
        rows["distance_m"] = dist
        rows["raster_prominence"] = np.where(ok, rprom[np.minimum(idx, len(rp) - 1)], np.nan)
    else:
        rows["matched"] = -1
        rows["distance_m"] = np.inf
        rows["raster_prominence"] = np.nan
    tol = np.maximum(prominence_tol_m, prominence_tol_rel * rows["prominence"].to_numpy())
    rows["recovered"] = (rows["matched"] >= 0) & (np.abs(rows["raster_prominence"] - rows["prominence"]) <= tol)
    big = rprom >= min_prominence_m
    if len(tp) and big.any():
        d_any, _ = cKDTree(tp).query(rp[big])
        extra = raster_peaks[big][d_any > distance_tol_m]
    else:
        extra = raster_peaks[big]
    return PeakComparison(rows, extra, float(distance_tol_m), (float(prominence_tol_m), float(prominence_tol_rel)))


@dataclass
class RoundTrip:
    """Result of :func:`roundtrip`: peak comparison, histogram errors, classification."""

    peaks: PeakComparison
    histograms: pd.DataFrame | None = None
    prediction: Any = None
    expected_label: str | None = None
    attrs: dict = field(default_factory=dict)

    def summary(self) -> dict[str, Any]:
        """One flat row: recovered share, extra share, max bin error, EMD, classification."""
        out = dict(self.attrs)
        out.update(self.peaks.summary())
        if self.histograms is not None and len(self.histograms):
            out["max_bin_error"] = float(self.histograms["max_bin_error"].max())
            out["max_bin_error_coarse"] = float(self.histograms["max_bin_error_coarse"].max())
            for name, row in self.histograms.iterrows():
                out[f"emd_{name}"] = float(row["emd"])
        if self.prediction is not None:
            p = self.prediction
            out["predicted"] = p.label
            out["n_disks"] = int(len(p.disks))
            if self.expected_label is not None:
                out["expected"] = self.expected_label
                out["disk_accuracy"] = float(np.mean(p.disks["predicted"] == self.expected_label)) if len(p.disks) else float("nan")
                out["vote_correct"] = bool(p.label == self.expected_label)
        return out


def roundtrip(
    dem,
    tree,
    *,
    min_prominence_m: float = 30.0,
    terrain_type: Any = None,
    model: Any = None,
    expected_label: str | None = None,
    distance_tol_m: float | None = None,
    analysis: Any = None,
    rng: Any = 0,
) -> RoundTrip:
    """Re-analyse ``dem`` (same engine, same eps) and compare it with ``tree``.

    Parameters
    ----------
    dem : rendered raster (DataArray in metres, e.g. from ``render_elevation``).
    tree : the tree it was rendered from.
    min_prominence_m : eps used for the analysis and the comparison.
    terrain_type : optional :class:`~orokit.synthesis.terrain_type.TerrainType`; the
        raster's Divide Tree is compared with its histograms (max bin error, EMD).
    model : optional trained region model (``orokit.classify.model.load_model``); the
        raster's disks are classified and voted.
    expected_label : the region the raster should be assigned to (defaults to the
        type's name when a type is given).
    distance_tol_m : peak location tolerance (default ``max(2 cells, 100 m)``).
    analysis : a ready :class:`~orokit.analysis.AnalysisResult` of ``dem`` (else computed).
    rng : seed of the disk placement for classification.
    """
    import orokit

    if analysis is None:
        analysis = orokit.analyze(dem, min_prominence_m=min_prominence_m, isolation=model is not None)
    res = abs(float(dem.rio.transform().a))
    tol = distance_tol_m if distance_tol_m is not None else max(2.0 * res, 100.0)
    comp = compare_peaks(tree, analysis.peaks, min_prominence_m=min_prominence_m, distance_tol_m=tol)
    hist = None
    if terrain_type is not None:
        from orokit.synthesis.fidelity import compare_to_type

        hist = compare_to_type(analysis.tree, terrain_type)
        if expected_label is None:
            expected_label = getattr(terrain_type, "name", None)
    pred = None
    if model is not None:
        from orokit.classify.features import features_from_dem
        from orokit.classify.predict import predict_regions

        feats = features_from_dem(dem, radius_m=model.radius_m, analysis=analysis, feature_set=model.feature_set,
                                  **model_feature_options(model.metadata, min_prominence_m=min_prominence_m), rng=rng)
        pred = predict_regions(model, feats, threshold=0.0)  # the best region, never "unknown"
    attrs = {"min_prominence_m": float(min_prominence_m), "raster_peaks": int(len(analysis.peaks)),
             "cell_size_m": res, "shape": f"{dem.shape[1]}x{dem.shape[0]}"}
    logger.info("round trip: %.1f %% of %d tree peaks recovered, %d extra",
                100 * comp.recovered_share, comp.n_tree, len(comp.extra))
    return RoundTrip(comp, hist, pred, expected_label, attrs)


def model_feature_options(metadata: dict[str, Any], *, min_prominence_m: float = 30.0) -> dict[str, Any]:
    """Feature options a model was trained with (eps, minimum peaks per disk, relative
    elevation), so the raster's disks are described the same way.

    Only missing (``None``) entries take the defaults (``min_prominence_m``, 20 peaks,
    ``"minmax"``): an explicit 0 is kept.

    Examples
    --------
    >>> model_feature_options({"min_prominence_m": 0.0, "min_peaks": 0})
    {'min_prominence_m': 0.0, 'min_peaks': 0, 'relative_elevation': 'minmax'}
    """
    eps = metadata.get("min_prominence_m")
    min_peaks = metadata.get("min_peaks")
    rel = metadata.get("relative_elevation")
    return {"min_prominence_m": float(eps if eps is not None else min_prominence_m),
            "min_peaks": int(min_peaks if min_peaks is not None else 20),
            "relative_elevation": rel if rel is not None else "minmax"}


def roundtrip_table(runs: list[dict[str, Any]]) -> pd.DataFrame:
    """Rows of :meth:`RoundTrip.summary` as a table (one row per run)."""
    return pd.DataFrame(runs)


def summary_json(rt: RoundTrip) -> str:
    """JSON of the summary plus the per-feature histogram table and classification."""
    d = {"summary": rt.summary()}
    if rt.histograms is not None:
        d["histograms"] = rt.histograms.reset_index().to_dict(orient="records")
    if rt.prediction is not None:
        d["classification"] = {k: v for k, v in rt.prediction.to_dict().items() if k != "disks"}
    return json.dumps(d, indent=2, default=lambda o: o.item() if hasattr(o, "item") else str(o))
