"""Feature sets of the region classifier: which numbers describe one disk.

A :class:`FeatureSet` fixes everything that turns the peaks of a disk into its feature
vector. It is recorded in every feature table and model, so a model computes features
of new ground exactly as it was trained (and refuses a table made otherwise).

- ``paper``: the reference mode, Argudo et al. (2019) Table 1: ten normalized
  histograms (176 numbers) of the peaks within R.
- ``orometry`` (default): chosen by the spatial hold-out (see
  ``reports/classification/ablation.md``). At R: five of the Table 1 histograms made
  cumulative (robust with the few peaks of a disk): dominance, dominance groups,
  isolation distance, key-saddle distance and prominence. Left out: the two direction
  histograms (they drift between parts of one region and rotate with the DEM) and the
  three disk-relative ones (relative elevation, relative prominence, relevance: they
  drift most between the halves of a region and between a DEM and its synthetic twin,
  and leaving them out costs nothing on the hold-out). Disk summaries that normalized
  histograms throw away: peak density (peaks >= eps per km2), a prominence spectrum
  (density of peaks >= 60 ... 800 m), the maximum prominence and quantiles of
  prominence, isolation (relative and in metres), key-saddle distance and dominance;
  quantiles of the elevation of the peaks and of their key saddles; and (session 5) the
  key saddles against their peaks (:data:`SADDLE_GROUPS`: relief, col ratio, saddle
  height; elevation and prominence only, so peak lists and synthetic trees have them):
  141 numbers.

Column names: ``<feature>_<bin>`` for histograms and ``log_density``,
``log_max_prominence``, ``q<percent>_<quantity>`` for summaries at R; at another radius
fraction f the name gets the prefix ``r<f>_`` (``r0.5_log_density``).
"""
from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from orokit.errors import SchemaError
from orokit.metrics.disk import (
    RELATIVE_ELEVATION_DEFAULT,
    RelativeElevation,
    axial_resultant,
    clamped_distance,
    dominance,
    relative_elevation,
    relative_prominence,
)
from orokit.sampling.histograms import HistogramSpec

__all__ = ["FeatureSet", "FEATURE_SET_NAMES", "TERRAIN_COLUMNS", "TERRAIN_GROUPS", "SUMMARY_QUANTILES", "disk_feature_vector", "saddle_features"]

FEATURE_SET_NAMES = ("orometry", "terrain", "paper")
#: histograms the default set leaves out: direction ones rotate with the DEM and drift between parts of a
#: region; disk-relative ones drift between the halves of a region and between a DEM and its synthetic twin
UNSTABLE_HISTOGRAMS = ("isolation_direction", "saddle_direction", "relative_elevation", "relative_prominence",
                       "relevance")
#: quantiles of the per-disk summaries
SUMMARY_QUANTILES = (0.25, 0.5, 0.75, 0.9)
_Q = tuple(f"q{int(round(100 * q))}" for q in SUMMARY_QUANTILES)
#: summary name -> the group it belongs to (Table 2 rows)
#: prominence thresholds (m) of the prominence spectrum: log density of peaks at least this prominent
SPECTRUM_THRESHOLDS_M = (60.0, 100.0, 200.0, 400.0, 800.0)
#: quantiles of the absolute elevation summaries
ELEVATION_QUANTILES = (0.1, 0.25, 0.5, 0.75, 0.9)
_EQ = tuple(f"q{int(round(100 * q))}" for q in ELEVATION_QUANTILES)
SUMMARY_GROUPS: dict[str, list[str]] = {
    "density": ["log_density"],
    "prominence_summary": ["log_max_prominence"] + [f"{q}_log_prominence" for q in _Q],
    "prominence_spectrum": [f"log_density_p{int(t)}" for t in SPECTRUM_THRESHOLDS_M],
    "isolation_summary": [f"{q}_isolation_distance" for q in _Q] + [f"{q}_log_isolation_m" for q in _Q],
    "saddle_distance_summary": [f"{q}_saddle_distance" for q in _Q],
    "dominance_summary": [f"{q}_dominance" for q in _Q],
}
ELEVATION_GROUPS: dict[str, list[str]] = {
    "elevation_summary": [f"{q}_elevation_km" for q in _EQ] + ["max_elevation_km"],
    "saddle_elevation_summary": [f"{q}_saddle_elevation_km" for q in _EQ],
}
#: spatial pattern of the peaks (rotation invariant): spacing, alignment of the key-saddle directions,
#: steepness towards the key saddle, rank correlation of elevation and prominence
PATTERN_GROUPS: dict[str, list[str]] = {
    "spacing": [f"{q}_log_spacing_m" for q in _Q] + ["clark_evans"],
    "alignment": ["saddle_alignment"],
    "steepness": [f"{q}_log_steepness" for q in _Q],
    "elevation_prominence_correlation": ["elevation_prominence_rank_correlation"],
}

#: key saddles against their peaks (rotation invariant, need only elevation and prominence, so they work on
#: every peak list): relief between the peaks and the key saddles, how high each key col sits between the
#: disk's lowest key saddle and its peak, and the key saddles' height within the disk's relief
SADDLE_GROUPS: dict[str, list[str]] = {
    "relief": ["relief_max_km", "relief_median_km", "relief_q90_q10_km"],
    "col_ratio": [f"{q}_col_ratio" for q in _Q],
    "saddle_height": [f"{q}_saddle_height" for q in _Q],
}

#: terrain (raster) features at R, computed from the DEM cells within the disk by
#: :mod:`orokit.classify.terrain` (inputs with a DEM only): slope quantiles and flat share, local relief in
#: ~1 and ~5 km windows, Laplacian curvature, hypsometry in the disk, spectral slope, drainage share
_TQ = (10, 25, 50, 75, 90)
TERRAIN_GROUPS: dict[str, list[str]] = {
    "slope": [f"q{q}_slope_deg" for q in _TQ] + ["flat_share"],
    "terrain_relief": [f"q{q}_relief_1km_km" for q in _TQ[1:]] + ["q50_relief_5km_km", "q90_relief_5km_km"],
    "curvature": ["q10_curvature_per_km", "q90_curvature_per_km", "iqr_curvature_per_km"],
    "hypsometry": ["hypsometric_integral"] + [f"q{q}_hypsometry" for q in _TQ[1:4]],
    "spectral_slope": ["spectral_slope"],
    "drainage": ["drainage_share"],
}
TERRAIN_COLUMNS = [c for cols in TERRAIN_GROUPS.values() for c in cols]

#: human-readable names of the summary groups (Table 2 rows)
SUMMARY_TITLES: dict[str, str] = {
    "density": "Peak density", "prominence_summary": "Prominence quantiles",
    "prominence_spectrum": "Prominence spectrum", "isolation_summary": "Isolation quantiles",
    "saddle_distance_summary": "Key saddle distance quantiles", "dominance_summary": "Dominance quantiles",
    "elevation_summary": "Peak elevation quantiles", "saddle_elevation_summary": "Key saddle elevation quantiles",
    "spacing": "Peak spacing", "alignment": "Key saddle direction alignment",
    "steepness": "Steepness to the key saddle",
    "elevation_prominence_correlation": "Elevation-prominence correlation",
    "relief": "Relief peaks to key saddles", "col_ratio": "Key col height ratio",
    "saddle_height": "Key saddle height in the disk",
    "slope": "Slope quantiles (DEM)", "terrain_relief": "Local relief 1 / 5 km (DEM)",
    "curvature": "Curvature (DEM)", "hypsometry": "Hypsometry in the disk (DEM)",
    "spectral_slope": "Spectral slope (DEM)", "drainage": "Drainage share (DEM)",
}


@dataclasses.dataclass(frozen=True)
class FeatureSet:
    """What a disk's feature vector holds.

    Parameters
    ----------
    name : str
        ``"paper"`` or ``"orometry"`` (or a custom name for experiments).
    spec : HistogramSpec
        Histogram bins (Table 1).
    radii : tuple of float
        Radius fractions of R at which the features are computed (1.0 = the disk).
    histograms : tuple of str
        Histogram features used (names of ``spec``); empty for none.
    summaries : bool
        Add the disk summaries (density, prominence, isolation, saddle distance, dominance).
    elevation : bool
        Add absolute elevation summaries: quantiles and maximum of the peaks' elevation and
        quantiles of their key saddles' elevation (km).
    cumulative : bool
        Cumulative instead of plain normalized histograms (direction histograms stay plain).
    saddles : bool
        Add the key saddles against their peaks (:data:`SADDLE_GROUPS`), with ``s = h - p``
        the key-saddle elevation and ``b`` the lowest key saddle of the disk: the relief
        ``max h - b``, ``median h - median s`` and ``q90 h - q10 s`` (km); quantiles of the
        col ratio ``(s - b) / (h - b)`` (0: the peak's col is the disk's lowest, near 1: a
        shallow col high on its parent's flank); quantiles of the saddle height
        ``(s - b) / (max h - b)``. They use elevation and prominence only.
    pattern : bool
        Add the spatial pattern of the peaks (:data:`PATTERN_GROUPS`): quantiles of the
        distance to the nearest other counted peak and the Clark-Evans ratio (mean of that
        distance over its expectation for random points of the same density); how strongly
        the key-saddle directions line up along one axis
        (:func:`~orokit.metrics.disk.axial_resultant`); quantiles of the steepness
        ``prominence / key-saddle distance``; Spearman correlation of elevation and
        prominence. All are unchanged by rotating or flipping the DEM. (Isolation directions
        are left out: on a grid, equidistant higher cells make them depend on the scan order.)
    terrain : bool
        Add terrain (raster) features at R (:data:`TERRAIN_GROUPS`, :mod:`orokit.classify.terrain`),
        computed from the DEM cells within each disk: only inputs with a DEM have them (not peak
        lists nor Divide Trees). Appended after the columns of every radius.
    terrain_cell_size_m : float or None
        Cell size (m) the DEM is averaged to, over whole blocks of cells, before the terrain
        features (90: a 30 m DEM over 3 x 3 cells; None: the DEM's own cells).
    """

    name: str
    spec: HistogramSpec
    radii: tuple[float, ...] = (1.0,)
    histograms: tuple[str, ...] | None = None
    summaries: bool = False
    elevation: bool = False
    cumulative: bool = False
    pattern: bool = False
    saddles: bool = False
    terrain: bool = False
    terrain_cell_size_m: float | None = 90.0

    def __post_init__(self) -> None:
        if not self.radii or any(not (0 < f <= 1.0) for f in self.radii) or len(set(self.radii)) != len(self.radii):
            raise SchemaError(f"feature set radii must be distinct fractions of R in (0, 1], got {self.radii!r}")
        if 1.0 not in self.radii:
            raise SchemaError(f"feature set radii must include 1.0 (the disk itself), got {self.radii!r}")
        if self.histograms is not None:
            unknown = [h for h in self.histograms if h not in self.spec.names]
            if unknown:
                raise SchemaError(f"unknown histogram features {unknown}; available: {self.spec.names}")

    @classmethod
    def paper(cls) -> FeatureSet:
        """Argudo et al. (2019) Table 1: ten histograms at R (176 numbers)."""
        return cls("paper", HistogramSpec.paper())

    @classmethod
    def orometry(cls) -> FeatureSet:
        """orokit's default: chosen by the spatial hold-out (see the module docstring)."""
        spec = HistogramSpec.paper()
        return cls("orometry", spec, radii=(1.0,), summaries=True, elevation=True, cumulative=True, saddles=True,
                   histograms=tuple(n for n in spec.names if n not in UNSTABLE_HISTOGRAMS))

    @classmethod
    def terrain_set(cls) -> FeatureSet:
        """``orometry`` plus the terrain (raster) features of each disk: for inputs with a DEM."""
        return dataclasses.replace(cls.orometry(), name="terrain", terrain=True)

    @classmethod
    def named(cls, name: str) -> FeatureSet:
        """The feature set called ``name`` (``"orometry"``, ``"terrain"`` or ``"paper"``)."""
        if name == "paper":
            return cls.paper()
        if name == "orometry":
            return cls.orometry()
        if name == "terrain":
            return cls.terrain_set()
        raise SchemaError(f"unknown feature set {name!r}; choose one of {', '.join(FEATURE_SET_NAMES)}")

    @property
    def histogram_spec(self) -> HistogramSpec:
        """The histogram features used (``spec`` restricted to :attr:`histograms`)."""
        return self.spec if self.histograms is None else self.spec.select(self.histograms)

    @staticmethod
    def _prefix(f: float) -> str:
        return "" if f == 1.0 else f"r{f:g}_"

    def _groups_at(self) -> dict[str, list[str]]:
        g: dict[str, list[str]] = dict(self.histogram_spec.groups())
        if self.summaries:
            g.update(SUMMARY_GROUPS)
        if self.elevation:
            g.update(ELEVATION_GROUPS)
        if self.saddles:
            g.update(SADDLE_GROUPS)
        if self.pattern:
            g.update(PATTERN_GROUPS)
        return g

    @property
    def columns(self) -> list[str]:
        """Feature columns in vector order (radius by radius, as listed in :attr:`radii`)."""
        base = [c for cols in self._groups_at().values() for c in cols]
        return [self._prefix(f) + c for f in self.radii for c in base] + (TERRAIN_COLUMNS if self.terrain else [])

    def groups(self) -> dict[str, list[str]]:
        """Feature group -> its columns at every radius (one Table 2 row each)."""
        g = {name: [self._prefix(f) + c for f in self.radii for c in cols] for name, cols in self._groups_at().items()}
        if self.terrain:
            g.update(TERRAIN_GROUPS)
        return g

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "spec": self.spec.to_dict(), "radii": list(self.radii),
                "histograms": None if self.histograms is None else list(self.histograms),
                "summaries": self.summaries, "elevation": self.elevation, "cumulative": self.cumulative,
                **({"saddles": True} if self.saddles else {}),  # absent when False: older files compare equal
                **({"pattern": True} if self.pattern else {}),
                **({"terrain": True, "terrain_cell_size_m": self.terrain_cell_size_m} if self.terrain else {})}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> FeatureSet:
        try:
            h = d.get("histograms")
            return cls(str(d["name"]), HistogramSpec.from_dict(d["spec"]),
                       radii=tuple(float(f) for f in d.get("radii", (1.0,))),
                       histograms=None if h is None else tuple(str(x) for x in h),
                       summaries=bool(d.get("summaries", False)), elevation=bool(d.get("elevation", False)),
                       cumulative=bool(d.get("cumulative", False)), pattern=bool(d.get("pattern", False)),
                       saddles=bool(d.get("saddles", False)), terrain=bool(d.get("terrain", False)),
                       terrain_cell_size_m=None if d.get("terrain_cell_size_m", 90.0) is None
                       else float(d.get("terrain_cell_size_m", 90.0)))
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise SchemaError(f"not a feature set dictionary ({exc!r}): {str(d)[:200]}") from exc


def _quantiles(v: NDArray[np.float64]) -> NDArray[np.float64]:
    v = v[np.isfinite(v)]
    return np.quantile(v, SUMMARY_QUANTILES) if len(v) else np.zeros(len(SUMMARY_QUANTILES))


def _elevation_quantiles(v: NDArray[np.float64]) -> NDArray[np.float64]:
    v = v[np.isfinite(v)]
    return np.quantile(v, ELEVATION_QUANTILES) / 1000.0 if len(v) else np.zeros(len(ELEVATION_QUANTILES))


def disk_feature_vector(elevation: NDArray, prominence: NDArray, saddle_distance_m: NDArray,
                        saddle_direction_deg: NDArray, isolation_m: NDArray, isolation_direction_deg: NDArray, *,
                        radius_m: float, feature_set: FeatureSet,
                        relative_elevation_convention: RelativeElevation = RELATIVE_ELEVATION_DEFAULT,
                        spacing_m: NDArray | None = None) -> NDArray[np.float64]:
    """Feature vector of the peaks of one disk of radius ``radius_m`` at one radius fraction.

    The arrays hold the counted peaks (prominence >= eps) within ``radius_m``; the
    per-peak metrics follow :mod:`orokit.metrics.disk`; ``spacing_m`` (needed by a
    feature set with ``pattern``) is each peak's distance to the nearest other counted
    peak (:func:`orokit.classify.features.nearest_peak_distance`). Returns the values of the
    feature set's columns for one radius (``len(columns) / len(radii)`` numbers). Every
    value is finite: an empty disk gives zero histograms and zero summaries.

    Examples
    --------
    >>> import numpy as np
    >>> fs = FeatureSet.paper()
    >>> v = disk_feature_vector(np.array([900.0, 500.0]), np.array([900.0, 100.0]), np.array([np.nan, 2e3]),
    ...                         np.array([np.nan, 90.0]), np.array([np.nan, 5e3]), np.array([np.nan, 0.0]),
    ...                         radius_m=1e4, feature_set=fs)
    >>> len(v), float(v[:20].sum())
    (176, 1.0)
    """
    h = np.asarray(elevation, dtype=float)
    p = np.asarray(prominence, dtype=float)
    n = len(h)
    dom = dominance(h, p)
    rel_h = relative_elevation(h, convention=relative_elevation_convention)
    rel_p = relative_prominence(p)
    iso = clamped_distance(isolation_m, radius_m)
    sad = clamped_distance(saddle_distance_m, radius_m)
    values = {"dominance": dom, "dominance_groups": dom, "relative_elevation": rel_h,
              "isolation_direction": np.mod(np.asarray(isolation_direction_deg, float), 360.0),
              "isolation_distance": iso,
              "saddle_direction": np.mod(np.asarray(saddle_direction_deg, float), 360.0),
              "saddle_distance": sad, "prominence": p, "relative_prominence": rel_p,
              "relevance": np.sqrt(rel_p * rel_h)}
    parts: list[NDArray[np.float64]] = []
    for fb in feature_set.histogram_spec.features:
        if fb.name not in values:
            raise SchemaError(f"no per-peak metric for histogram feature {fb.name!r}")
        c = fb.counts(values[fb.name]).astype(float)
        total = c.sum()
        c = c / total if total > 0 else c
        if feature_set.cumulative and "direction" not in fb.name:
            c = np.cumsum(c)
        parts.append(c)
    if feature_set.summaries:
        area_km2 = np.pi * (radius_m / 1000.0) ** 2
        lp = np.log10(np.maximum(p, 1.0))
        parts.append(np.array([np.log10(n / area_km2 + 1e-3), lp.max() if n else 0.0]))
        parts.append(_quantiles(lp))
        parts.append(np.log10(np.array([np.sum(p >= t) for t in SPECTRUM_THRESHOLDS_M]) / area_km2 + 1e-3))
        parts.append(_quantiles(iso))
        iso_m = np.asarray(isolation_m, dtype=float)
        # unknown isolation (nothing higher in the data) counts as 100 km
        parts.append(_quantiles(np.log10(np.where(np.isfinite(iso_m), iso_m, 1e5) + 1.0)))
        parts.append(_quantiles(sad))
        parts.append(_quantiles(dom))
    if feature_set.elevation:
        parts.append(_elevation_quantiles(h))
        parts.append(np.array([np.nanmax(h) / 1000.0 if n else 0.0]))
        parts.append(_elevation_quantiles(h - p))  # key-saddle elevations
    if feature_set.saddles:
        parts.append(saddle_features(h, p))
    if feature_set.pattern:
        parts.append(_pattern(h, p, saddle_distance_m, saddle_direction_deg, spacing_m, radius_m))
    return np.concatenate(parts) if parts else np.zeros(0)


def saddle_features(elevation: NDArray, prominence: NDArray) -> NDArray[np.float64]:
    """The :data:`SADDLE_GROUPS` values of the peaks of one disk (see :class:`FeatureSet`); zeros when empty.

    Examples
    --------
    >>> saddle_features(np.array([1000.0, 600.0]), np.array([800.0, 200.0])).round(2).tolist()[:3]
    [0.8, 0.5, 0.74]
    """
    h = np.asarray(elevation, dtype=float)
    p = np.asarray(prominence, dtype=float)
    ok = np.isfinite(h) & np.isfinite(p)
    h, p = h[ok], p[ok]
    if len(h) == 0:
        return np.zeros(sum(len(c) for c in SADDLE_GROUPS.values()))
    s = h - p
    base = float(s.min())
    top = float(h.max())
    relief = np.array([top - base, np.median(h) - np.median(s), np.quantile(h, 0.9) - np.quantile(s, 0.1)]) / 1000.0
    col = (s - base) / np.maximum(h - base, 1.0)
    height = (s - base) / max(top - base, 1.0)
    return np.concatenate([relief, _quantiles(col), _quantiles(height)])


def _pattern(h: NDArray, p: NDArray, saddle_distance_m: NDArray, saddle_direction_deg: NDArray,
             spacing_m: NDArray | None, radius_m: float) -> NDArray[np.float64]:
    """The :data:`PATTERN_GROUPS` values of one disk (see :class:`FeatureSet`)."""
    if spacing_m is None:
        raise SchemaError("feature sets with pattern=True need the peaks' spacing_m (distance to the nearest peak)")
    n = len(h)
    s = np.asarray(spacing_m, dtype=float)
    s_ok = s[np.isfinite(s) & (s > 0)]
    area_m2 = np.pi * radius_m ** 2
    # Clark & Evans (1954): mean nearest-neighbour distance / 0.5 / sqrt(density); 1 for random points
    clark_evans = float(s_ok.mean() / (0.5 / np.sqrt(n / area_m2))) if len(s_ok) and n else 0.0
    alignment = abs(axial_resultant(saddle_direction_deg))
    d = np.asarray(saddle_distance_m, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        steep = np.log10(p / d)
    if n >= 2 and np.ptp(h) > 0 and np.ptp(p) > 0:
        from scipy.stats import spearmanr

        rho = float(spearmanr(h, p).statistic)
    else:
        rho = 0.0
    return np.concatenate([_quantiles(np.log10(s_ok)), [clark_evans],
                           [alignment],
                           _quantiles(steep), [rho if np.isfinite(rho) else 0.0]])
