"""Terrain types: the orometric statistics of a region, as synthesis targets.

A :class:`TerrainType` holds, for one region, fine histograms of peak elevation,
prominence, dominance, isolation distance and direction, key-saddle distance and
direction, the peak density (peaks with prominence >= ``min_prominence_m`` per
km2) and the preferred ridge exponent ``rho`` of the paper's minimum spanning tree
weight (Argudo et al. 2019, section 5, doi:10.1145/3355089.3356535). It is saved
as a small versioned JSON file and can be edited (scale prominence, shift
elevations, replace a histogram) into a new valid type.
"""
from __future__ import annotations

import dataclasses
import json
import logging
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from orokit._typing import PathLike, SeedLike
from orokit.errors import InputError, SchemaError

logger = logging.getLogger(__name__)

__all__ = [
    "FEATURES",
    "FeatureHistogram",
    "TerrainType",
    "TYPE_FORMAT",
    "TYPE_VERSION",
    "load_terrain_type",
    "loads_terrain_type",
]

TYPE_FORMAT = "orokit.terrain_type"
TYPE_VERSION = 1

#: feature -> (unit, kind); kind "linear" (magnitudes) or "circular" (directions, degrees)
FEATURES: dict[str, tuple[str, str]] = {
    "elevation": ("m", "linear"),
    "prominence": ("m", "linear"),
    "dominance": ("1", "linear"),
    "isolation_distance": ("m", "linear"),
    "isolation_direction": ("deg", "circular"),
    "saddle_distance": ("m", "linear"),
    "saddle_direction": ("deg", "circular"),
}

#: number of bins of the fine synthesis histograms
N_LINEAR_BINS = 40
N_DIRECTION_BINS = 24


@dataclasses.dataclass(frozen=True)
class FeatureHistogram:
    """Histogram of one feature: bin ``edges`` and non-negative ``counts``.

    ``open_last`` means values above the last edge were counted in the last bin
    (heavy tails: prominence, distances); sampling draws them inside the last bin.
    """

    edges: tuple[float, ...]
    counts: tuple[float, ...]
    open_last: bool = False

    def __post_init__(self) -> None:
        e = np.asarray(self.edges, float)
        c = np.asarray(self.counts, float)
        if e.ndim != 1 or e.size < 2 or not np.all(np.isfinite(e)) or not np.all(np.diff(e) > 0):
            raise SchemaError(
                f"histogram edges must be >= 2 finite, strictly increasing numbers; got {list(self.edges)[:8]}"
            )
        if c.shape != (e.size - 1,):
            raise SchemaError(f"a histogram with {e.size} edges needs {e.size - 1} counts, got {c.size}")
        if not np.all(np.isfinite(c)) or np.any(c < 0):
            raise SchemaError("histogram counts must be finite and >= 0")
        if c.sum() <= 0:
            raise SchemaError("histogram is empty (all counts are 0): nothing to sample targets from")

    @property
    def n_bins(self) -> int:
        return len(self.counts)

    def probabilities(self) -> np.ndarray:
        """Counts normalised to sum 1."""
        c = np.asarray(self.counts, float)
        return c / c.sum()

    def bin_index(self, values: np.ndarray) -> np.ndarray:
        """Bin of each value (-1 outside; above the last edge -> last bin if open)."""
        e = np.asarray(self.edges, float)
        v = np.asarray(values, float)
        idx = np.searchsorted(e, v, side="right") - 1
        idx = np.where(v == e[-1], e.size - 2, idx)
        if self.open_last:
            idx = np.where(v > e[-1], e.size - 2, idx)
        return np.where((idx < 0) | (idx > e.size - 2) | ~np.isfinite(v), -1, idx)

    def histogram(self, values: np.ndarray) -> np.ndarray:
        """Normalised histogram of ``values`` on these bins (values outside ignored)."""
        idx = self.bin_index(values)
        idx = idx[idx >= 0]
        h = np.bincount(idx, minlength=self.n_bins).astype(float)
        return h / h.sum() if h.sum() > 0 else h

    def sample(self, n: int, rng: SeedLike = None, *, stratified: bool = True) -> np.ndarray:
        """Draw ``n`` values (uniform inside bins).

        With ``stratified`` the quantile levels are ``(k + u_k) / n`` (one per
        stratum) so the sample histogram matches the target up to one count per bin.
        """
        rng = np.random.default_rng(rng)
        n = int(n)
        if n <= 0:
            return np.empty(0)
        p = self.probabilities()
        cdf = np.concatenate([[0.0], np.cumsum(p)])
        cdf[-1] = 1.0
        if stratified:
            u = (np.arange(n) + rng.random(n)) / n
            rng.shuffle(u)
        else:
            u = rng.random(n)
        b = np.clip(np.searchsorted(cdf, u, side="right") - 1, 0, p.size - 1)
        width = np.where(p[b] > 0, p[b], 1.0)
        frac = np.clip((u - cdf[b]) / width, 0.0, 1.0)
        e = np.asarray(self.edges, float)
        return e[b] + frac * (e[b + 1] - e[b])

    def to_dict(self) -> dict[str, Any]:
        return {"edges": [float(v) for v in self.edges], "counts": [float(v) for v in self.counts],
                "open_last": bool(self.open_last)}

    @classmethod
    def from_values(cls, values: np.ndarray, edges: np.ndarray, *, open_last: bool = False) -> "FeatureHistogram":
        """Histogram of ``values`` on ``edges``."""
        tmp = cls(tuple(float(v) for v in edges), tuple([1.0] * (len(edges) - 1)), open_last)
        idx = tmp.bin_index(values)
        counts = np.bincount(idx[idx >= 0], minlength=len(edges) - 1).astype(float)
        return cls(tmp.edges, tuple(float(c) for c in counts), open_last)


def _nice_step(span: float, n: int) -> float:
    raw = max(span, 1e-9) / n
    mag = 10 ** math.floor(math.log10(raw))
    for m in (1, 2, 2.5, 5, 10):
        if m * mag >= raw:
            return m * mag
    return 10 * mag  # pragma: no cover


def _linear_edges(values: np.ndarray, *, lo: float | None, q_hi: float, n: int) -> tuple[np.ndarray, bool]:
    v = values[np.isfinite(values)]
    lo_v = float(v.min()) if lo is None else lo
    hi_v = float(np.quantile(v, q_hi)) if q_hi < 1 else float(v.max())
    open_last = q_hi < 1 and hi_v < float(v.max())
    if hi_v <= lo_v:
        hi_v = lo_v + max(abs(lo_v) * 0.01, 1.0)
    step = _nice_step(hi_v - lo_v, n)
    start = math.floor(lo_v / step) * step if lo is None else lo
    k = max(1, math.ceil((hi_v - start) / step - 1e-9))
    return start + step * np.arange(k + 1), open_last


def _direction_edges(n: int = N_DIRECTION_BINS) -> np.ndarray:
    return np.linspace(0.0, 360.0, n + 1)


@dataclasses.dataclass(frozen=True)
class TerrainType:
    """Orometric statistics of a region, used as the target of Divide Tree synthesis.

    Attributes
    ----------
    name : str
    histograms : mapping feature -> :class:`FeatureHistogram` for every name in
        :data:`FEATURES` (elevation, prominence in metres; dominance; isolation and
        key-saddle distance in metres and direction in degrees counter-clockwise from
        east).
    peak_density_per_km2 : float
        Peaks with prominence >= ``min_prominence_m`` per km2.
    rho : float
        Exponent of the ridge weight ``|Pi - Pj| / min(h_i, h_j) ** rho``.
    min_prominence_m : float
        The prominence threshold ``eps`` the statistics were computed with.
    isolation_basis : "peaks" (distance to the nearest higher peak of the tree, what a
        synthesized Divide Tree can measure) or "terrain" (nearest higher cell).
    provenance : free metadata (source, area, counts, edits).
    source_crs : WKT of the CRS of the data the type was measured on (None: a local grid).
    source_center : ``(lon, lat)`` of the centre of that data (None: not georeferenced);
        ``orokit synthesize`` places new terrain there by default.
    texture : ``{"rms_m", "beta", "largest_m"}`` of the source DEM's short-wavelength
        texture (:func:`orokit.raster.noise.texture_spectrum`; None: no DEM was seen), which
        the renderer adds back (:class:`orokit.raster.params.RenderParams`).
    disks : per-disk statistics of the source (:mod:`orokit.synthesis.disks`): quantiles over
        10 km disks inside the data of their peak count, maximum prominence and ``top_rank``
        (share of the peaks higher than the disk's highest); None for types made before it or
        from data narrower than 20 km. The dart throwing follows ``top_rank``. Its optional
        ``border_rank`` (:func:`orokit.synthesis.disks.border_rank`: mean elevation rank of the
        peaks by distance to the data border) shapes the default C_H, so a twin of a DEM cropped
        around its relief holds its high ground inside as the DEM does; its optional ``median_rank``
        (quantiles of the disks' median elevation rank; types before session 18 lack it) and ``peak_relief_m``
        (quantiles of the spread of the disks' peak elevations; before session 19 none) are the span of the
        source's disks that ``follow_disk_rank`` synthesis keeps a twin's disks inside.
    bands : optional joint statistics (orokit): ``{"elevation_bins": [i0, ..., iK],
        "prominence": [[...]] * K, "dominance": [[...]] * K}``: prominence and dominance
        counts (on the marginal histograms' bins) of the peaks whose elevation falls in
        elevation bins ``i_k .. i_{k+1} - 1``. Synthesis draws saddle targets per band so
        prominence stays paired with elevation as in the real region. Edits that change
        the elevation bins or hand-edit those histograms drop them.
    gradient : histogram of ``(h_q - h_p) / d(p, q)`` from every peak p to its nearest higher
        peak q (m/m; None for types made before it). The dart throwing follows it, so a low peak
        lands as far from the higher peaks around it as in the source (issue 11: with the C_H
        alone, neighbouring twin peaks were too alike in elevation, or too close to a much higher
        one). Edits of the elevation or isolation-distance histograms drop it.
    ridge_contrast : :func:`orokit.synthesis.ridges.ridge_contrast` of the source tree: median
        ``|h_a - h_b|`` over its ridges against the median over the Delaunay edges of its peaks
        (None: no tree was seen). Synthesis builds its ridges to the same value (issue 11: the
        paper's MST joined neighbours of similar height, so twin ridges were too gentle). A ratio,
        so edits keep it.
    neighbour_gradient : median ``|h_p - h_q| / d(p, q)`` from every peak p to its nearest peak q
        (m/m; None: not recorded). Synthesis gives its default C_H a ~1 km component whose
        weight brings the tree's median to this value (issue 11: the twins' neighbouring peaks
        were too alike, e.g. rockies 0.05 against 0.10). Edits of the elevation (other than a
        shift) or isolation-distance histograms, or of the density, drop it.
    max_ridge_slope : 99th percentile over the source tree's ridges of ``(h_a + h_b - 2 s) / |AB|``
        (both ends' drops to the saddle over the ridge's length, m/m; None: not recorded).
        Synthesis never lowers a saddle below it (issue 11: the twins had short ridges with deep
        saddles, twice the real trees' 99th percentile in steep regions, the renders' curvature
        tails). Edits of any histogram but the directions, or of the density, drop it.
    saddle_level : :func:`orokit.synthesis.saddles.saddle_level` of the source tree: how far its nearby
        saddles lie from one level, over the local relief (dimensionless; None: not recorded). With
        ``follow_saddle_level`` synthesis weights a level term of its saddle OT until the tree's value is
        no higher (issue 11, session 17: the OT's saddles scattered around the peaks' levels, a dome field's
        twin 0.21 against the real 0.08, and the renders sank their low ground). An elevation shift keeps it;
        other edits of a linear histogram, or of the density, drop it.
    forced_tail : share of the source tree's keyed peaks whose forced prominence
        (:func:`orokit.synthesis.saddles.forced_prominence`: every saddle at its ridge's lower end) reaches the
        90th percentile of their prominences: how often a high peak stands among much lower ones whatever its
        saddles (None: not recorded). With ``follow_forced_tail`` synthesis joins the peaks along higher ground
        until its tree's share is no larger (issue 11, session 19: twins 2-6 times the real share in every range,
        which no saddle assignment can undo). Edited like ``saddle_level``.
    plain_dominance : histogram on [0, 1] of :func:`orokit.synthesis.saddles.plain_dominance` over the source
        tree's peaks: each peak's prominence over its height above the lowest saddle of the 16 nearest ridges
        (None: not recorded, types before session 19). With ``follow_plain_dominance`` the saddle OT matches it
        as a third feature (issue 11, session 19: a dune field's real dunes stand with 90 % of their height
        above the local plain (median), its twins' 74 %). Edits as for ``saddle_level``.
    """

    name: str
    histograms: Mapping[str, FeatureHistogram]
    peak_density_per_km2: float
    rho: float = 1.0
    min_prominence_m: float = 30.0
    isolation_basis: str = "peaks"
    provenance: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    bands: Mapping[str, Any] | None = None
    source_crs: str | None = None
    source_center: tuple[float, float] | None = None
    texture: Mapping[str, float] | None = None
    disks: Mapping[str, Any] | None = None
    gradient: FeatureHistogram | None = None
    ridge_contrast: float | None = None
    neighbour_gradient: float | None = None
    max_ridge_slope: float | None = None
    saddle_level: float | None = None
    forced_tail: float | None = None
    plain_dominance: FeatureHistogram | None = None

    def __post_init__(self) -> None:
        missing = set(FEATURES) - set(self.histograms)
        if missing:
            raise SchemaError(f"terrain type {self.name!r} lacks histograms {sorted(missing)}; "
                              f"a type needs all of {list(FEATURES)}")
        if not (np.isfinite(self.peak_density_per_km2) and self.peak_density_per_km2 > 0):
            raise SchemaError(f"peak density must be > 0 peaks/km2, got {self.peak_density_per_km2!r}")
        if not (np.isfinite(self.rho) and 0 <= self.rho <= 4):
            raise SchemaError(f"rho must be in [0, 4] (the paper uses 0, 1 or 2), got {self.rho!r}")
        if not (np.isfinite(self.min_prominence_m) and self.min_prominence_m >= 0):
            raise SchemaError(f"min_prominence_m must be >= 0, got {self.min_prominence_m!r}")
        if self.isolation_basis not in ("peaks", "terrain"):
            raise SchemaError(f"isolation_basis must be 'peaks' or 'terrain', got {self.isolation_basis!r}")
        if self.bands is not None:
            _check_bands(self.bands, self.histograms)
        if self.source_center is not None:
            lon, lat = (float(v) for v in self.source_center)
            if not (np.isfinite(lon) and np.isfinite(lat) and -180 <= lon <= 360 and -90 <= lat <= 90):
                raise SchemaError(f"source_center must be (lon, lat) in degrees, got {self.source_center!r}")
            object.__setattr__(self, "source_center", (lon, lat))
        if self.texture is not None:
            t = {k: float(v) for k, v in dict(self.texture).items()}
            if not (np.isfinite(t.get("rms_m", np.nan)) and t["rms_m"] >= 0 and np.isfinite(t.get("beta", np.nan))):
                raise SchemaError(f"texture needs a finite rms_m >= 0 and beta, got {self.texture!r}")
            object.__setattr__(self, "texture", t)
        if self.gradient is not None and not isinstance(self.gradient, FeatureHistogram):
            raise SchemaError(f"gradient must be a FeatureHistogram or None, got {type(self.gradient).__name__}")
        if self.gradient is not None and self.gradient.edges[0] < 0:
            raise SchemaError(f"gradient histogram starts below 0 ({self.gradient.edges[0]:g}); the gradient to "
                              "a higher peak is >= 0")
        if self.ridge_contrast is not None:
            c = float(self.ridge_contrast)
            if not (np.isfinite(c) and c >= 0):
                raise SchemaError(f"ridge_contrast must be a finite number >= 0 or None, got {self.ridge_contrast!r}")
            object.__setattr__(self, "ridge_contrast", c)
        for name, hi, what in (("neighbour_gradient", np.inf, "a finite number >= 0 (m/m)"),
                               ("max_ridge_slope", np.inf, "a finite number >= 0 (m/m)"),
                               ("saddle_level", 1.0, "a number in [0, 1]"), ("forced_tail", 1.0, "a number in [0, 1]")):
            v = getattr(self, name)
            if v is not None:
                try:
                    c = float(v)
                except (TypeError, ValueError):
                    c = float("nan")
                if not (np.isfinite(c) and 0 <= c <= hi):
                    raise SchemaError(f"{name} must be {what} or None, got {v!r}")
                object.__setattr__(self, name, c)
        if self.plain_dominance is not None:
            h = self.plain_dominance
            if not isinstance(h, FeatureHistogram):
                raise SchemaError(f"plain_dominance must be a FeatureHistogram or None, got {type(h).__name__}")
            if h.edges[0] < 0 or h.edges[-1] > 1:
                raise SchemaError(f"plain_dominance histogram must lie in [0, 1], got edges {h.edges[0]:g}.."
                                  f"{h.edges[-1]:g}; re-create the type with `orokit type`")
        if self.disks is not None:
            from orokit.synthesis.disks import check_disk_quantiles

            object.__setattr__(self, "disks", check_disk_quantiles(self.disks))
        e = self.histograms["elevation"]
        if e.edges[-1] <= 0:
            raise SchemaError("the elevation histogram lies entirely at or below 0 m: peaks need positive elevations")

    # ------------------------------------------------------------ construction
    @classmethod
    def from_peaks(
        cls,
        peaks: pd.DataFrame,
        *,
        area_km2: float,
        min_prominence_m: float = 30.0,
        tree: Any = None,
        isolation_basis: str = "peaks",
        rho: float | None = None,
        name: str = "type",
        provenance: Mapping[str, Any] | None = None,
        crs: Any = None,
        extent: tuple[float, float, float, float] | None = None,
    ) -> "TerrainType":
        """Type from a peak table (``orokit analyze`` columns).

        Parameters
        ----------
        peaks : needs ``x``, ``y`` (in ``crs``), ``elevation``, ``prominence`` (metres),
            ``saddle_x``, ``saddle_y`` (NaN for roots); with ``isolation_basis="terrain"``
            also ``isolation`` (metres), ``isolation_x``, ``isolation_y``.
        area_km2 : area the peaks were found in (for the density).
        min_prominence_m : only peaks with prominence >= this count.
        tree : optional :class:`DivideTree` of the same peaks, used to pick rho.
        isolation_basis : "peaks" (default, nearest higher peak among the counted peaks,
            comparable with synthesized trees) or "terrain" (the table's isolation).
        rho : ridge exponent; estimated from ``tree`` when None (default 1).
        crs : CRS of x/y. Geographic (lon/lat): distances are WGS84 geodesics and
            directions geodesic azimuths (through :mod:`orokit.geodesy`), the nearest
            higher peak is searched in a local azimuthal equidistant projection.
            Projected: the CRS's linear unit is converted to metres. None: metres.
        extent : ``(xmin, ymin, xmax, ymax)`` of the data in ``crs`` (for the per-disk
            statistics, ``disks``); default: the peaks' bounding box.

        Raises
        ------
        InputError
            Missing columns, non-positive area or fewer than 3 peaks above the threshold.
        """
        from orokit.geodesy import point_distance
        from orokit.metrics.disk import dominance
        from orokit.synthesis.orometry import nearest_higher_peak, planar_xy

        need = {"x", "y", "elevation", "prominence", "saddle_x", "saddle_y"}
        if isolation_basis == "terrain":
            need |= {"isolation", "isolation_x", "isolation_y"}
        miss = need - set(peaks.columns)
        if miss:
            raise InputError(f"peak table lacks columns {sorted(miss)} needed for a terrain type; "
                             "use the peaks.parquet written by `orokit analyze`")
        if not (np.isfinite(area_km2) and area_km2 > 0):
            raise InputError(f"area_km2 must be > 0, got {area_km2!r}")
        p = peaks[peaks["prominence"].to_numpy(float) >= min_prominence_m]
        if len(p) < 3:
            raise InputError(
                f"only {len(p)} peaks have prominence >= {min_prominence_m} m: too few for a terrain type; "
                "use a larger region or a lower min_prominence_m"
            )
        x, y = p["x"].to_numpy(float), p["y"].to_numpy(float)
        z = p["elevation"].to_numpy(float)
        prom = p["prominence"].to_numpy(float)
        sx, sy = p["saddle_x"].to_numpy(float), p["saddle_y"].to_numpy(float)
        keyed = np.isfinite(sx) & np.isfinite(sy)
        near = nearest_higher_peak(*planar_xy(x, y, crs), z)
        ok = near >= 0
        nx_ = np.where(ok, x[np.maximum(near, 0)], np.nan)
        ny_ = np.where(ok, y[np.maximum(near, 0)], np.nan)
        near_d, near_dir = point_distance(x, y, nx_, ny_, crs=crs)
        with np.errstate(invalid="ignore", divide="ignore"):
            grad = (z[np.maximum(near, 0)] - z) / near_d
        grad = grad[ok & np.isfinite(grad)]
        if isolation_basis == "terrain":
            ix, iy = p["isolation_x"].to_numpy(float), p["isolation_y"].to_numpy(float)
            iso = p["isolation"].to_numpy(float)
            _, iso_dir = point_distance(x, y, ix, iy, crs=crs)
        else:
            ix, iy, iso, iso_dir = nx_, ny_, near_d, near_dir
        iso = np.where(np.isfinite(ix) & np.isfinite(iy), iso, np.nan)
        saddle_dist, saddle_dir = point_distance(x, y, sx, sy, crs=crs)
        has_iso = np.isfinite(iso)
        values = {
            "elevation": z,
            "prominence": prom[keyed],
            "dominance": dominance(z[keyed], prom[keyed]),
            "isolation_distance": iso[has_iso],
            "isolation_direction": iso_dir[has_iso],
            "saddle_distance": saddle_dist[keyed],
            "saddle_direction": saddle_dir[keyed],
        }
        for k, v in values.items():
            if np.isfinite(v).sum() < 2:
                raise InputError(f"fewer than 2 finite {k} values among {len(p)} peaks: cannot build a type")
        hists = {}
        n = N_LINEAR_BINS
        e, _ = _linear_edges(values["elevation"], lo=None, q_hi=1.0, n=n)
        hists["elevation"] = FeatureHistogram.from_values(values["elevation"], e)
        e, op = _linear_edges(values["prominence"], lo=float(min_prominence_m), q_hi=0.99, n=n)
        hists["prominence"] = FeatureHistogram.from_values(values["prominence"], e, open_last=op)
        hists["dominance"] = FeatureHistogram.from_values(values["dominance"], np.linspace(0, 1, n + 1))
        for k in ("isolation_distance", "saddle_distance"):
            e, op = _linear_edges(values[k], lo=0.0, q_hi=0.99, n=n)
            hists[k] = FeatureHistogram.from_values(values[k], e, open_last=op)
        for k in ("isolation_direction", "saddle_direction"):
            hists[k] = FeatureHistogram.from_values(values[k], _direction_edges())
        gradient = None
        if grad.size >= 2:
            e, op = _linear_edges(np.maximum(grad, 0.0), lo=0.0, q_hi=0.99, n=n)
            gradient = FeatureHistogram.from_values(np.maximum(grad, 0.0), e, open_last=op)
        if rho is None:
            rho = estimate_rho(tree, min_prominence_m) if tree is not None else 1.0
        contrast = tree_ridge_contrast(tree, min_prominence_m) if tree is not None else None
        ridge_slope = tree_max_ridge_slope(tree, min_prominence_m) if tree is not None else None
        level = tree_saddle_level(tree, min_prominence_m) if tree is not None else None
        forced = tree_forced_tail(tree, min_prominence_m) if tree is not None else None
        plain = tree_plain_dominance(tree, min_prominence_m) if tree is not None else None
        prov = {
            "area_km2": float(area_km2),
            "n_peaks": int(len(p)),
            "n_keyed": int(keyed.sum()),
            "edits": [],
        }
        prov.update(dict(provenance or {}))
        bands = _elevation_bands(z[keyed], values["prominence"], values["dominance"], hists)
        src_crs, center = source_location(crs, 0.5 * (x.min() + x.max()), 0.5 * (y.min() + y.max()))
        return cls(name, hists, len(p) / float(area_km2), float(rho), float(min_prominence_m),
                   isolation_basis, prov, bands, source_crs=src_crs, source_center=center,
                   disks=_disk_record(x, y, z, prom, crs, extent, min_prominence_m), gradient=gradient,
                   ridge_contrast=contrast, neighbour_gradient=_neighbour_gradient(*planar_xy(x, y, crs), z),
                   max_ridge_slope=ridge_slope, saddle_level=level, forced_tail=forced,
                   plain_dominance=plain)

    @classmethod
    def from_divide_tree(cls, tree: Any, *, area_km2: float, min_prominence_m: float = 30.0,
                         name: str = "type", rho: float | None = None,
                         provenance: Mapping[str, Any] | None = None) -> "TerrainType":
        """Type from a :class:`DivideTree` (e.g. a reference TXT tree), pruned at ``eps``."""
        from orokit.synthesis.orometry import tree_orometry

        pruned = tree.prune(min_prominence_m)
        table = tree_orometry(pruned)
        frame = pd.concat([pruned.peaks[["x", "y", "elevation"]].reset_index(drop=True),
                           table[["prominence", "saddle_x", "saddle_y"]].reset_index(drop=True)], axis=1)
        return cls.from_peaks(frame, area_km2=area_km2, min_prominence_m=min_prominence_m,
                              tree=pruned, name=name, rho=rho, provenance=provenance, crs=pruned.crs)

    @classmethod
    def from_analysis(cls, result: Any, *, min_prominence_m: float | None = None, name: str | None = None,
                      isolation_basis: str = "peaks", rho: float | None = None) -> "TerrainType":
        """Type from an :class:`orokit.analysis.AnalysisResult` or an ``orokit analyze`` folder.

        The area is that of the analysed grid (``shape`` and ``transform`` recorded in
        ``analysis.json``) on the ground: exact ellipsoidal cell areas for lon/lat grids.
        Distances and directions are in metres and degrees whatever the CRS (see
        :meth:`from_peaks`).
        """
        from orokit.data import portable_path
        from orokit.sampling.grid import analysis_grid, grid_area_km2

        src = None
        if not hasattr(result, "peaks"):
            from orokit.analysis import read_analysis

            src = str(result)
            result = read_analysis(result)
        attrs = dict(getattr(result, "attrs", {}) or {})
        eps = float(attrs.get("min_prominence_m", 30.0) if min_prominence_m is None else min_prominence_m)
        peaks = pd.DataFrame(result.peaks.drop(columns="geometry", errors="ignore"))
        transform, grid_crs, shape = analysis_grid(attrs, peaks)
        crs = getattr(result, "crs", None)
        crs = grid_crs if crs is None else crs
        area = float(attrs["area_km2"]) if "area_km2" in attrs else grid_area_km2(transform, crs, shape)
        name = name or Path(str(attrs.get("source") or src or "type")).stem
        extent = None
        if transform is not None and shape is not None:
            (ax, ay), (bx, by) = transform * (0, 0), transform * (shape[1], shape[0])
            extent = (min(ax, bx), min(ay, by), max(ax, bx), max(ay, by))
        tt = cls.from_peaks(peaks, area_km2=area, min_prominence_m=eps,
                            tree=getattr(result, "tree", None), isolation_basis=isolation_basis,
                            rho=rho, name=name, provenance={"source": portable_path(attrs.get("source") or src)},
                            crs=crs, extent=extent)
        if transform is not None and shape is not None and crs is not None and not attrs.get("local_grid"):
            cx, cy = transform * (0.5 * shape[1], 0.5 * shape[0])
            src_crs, center = source_location(crs, cx, cy)
            tt = dataclasses.replace(tt, source_crs=src_crs, source_center=center)
        return tt

    def with_texture(self, rms_m: float, beta: float, largest_m: float = 1000.0) -> "TerrainType":
        """New type with the source DEM's texture (:func:`orokit.raster.noise.texture_spectrum`)."""
        return dataclasses.replace(self, texture={"rms_m": float(rms_m), "beta": float(beta),
                                                  "largest_m": float(largest_m)})

    # --------------------------------------------------------------- editing
    def _edited(self, note: str, **changes: Any) -> "TerrainType":
        prov = dict(self.provenance)
        prov["edits"] = [*prov.get("edits", []), note]
        return dataclasses.replace(self, provenance=prov, **changes)

    def with_histogram(self, feature: str, edges: Any, counts: Any, *, open_last: bool | None = None) -> "TerrainType":
        """New type with one histogram replaced (validated)."""
        _check_feature(feature)
        old = self.histograms[feature]
        h = FeatureHistogram(tuple(float(v) for v in edges), tuple(float(v) for v in counts),
                             old.open_last if open_last is None else open_last)
        _check_range(feature, h)
        hists = dict(self.histograms)
        hists[feature] = h
        keep = self.bands if feature not in ("elevation", "prominence", "dominance") else None
        return self._edited(f"set {feature} histogram", histograms=hists, bands=keep,
                            **self._relief_after(feature))

    def with_counts(self, feature: str, counts: Any) -> "TerrainType":
        """New type with the counts of one histogram replaced (hand-edited bins)."""
        _check_feature(feature)
        return self.with_histogram(feature, self.histograms[feature].edges, counts)

    def scaled(self, feature: str, factor: float) -> "TerrainType":
        """New type with a linear feature's values multiplied by ``factor`` (> 0).

        Features are edited independently: scaling prominence leaves the dominance
        histogram as it is (scale or edit it separately if wanted). Scaled dominance
        is clipped to [0, 1], the excess mass going to the last bin.
        """
        _check_feature(feature)
        if FEATURES[feature][1] != "linear":
            raise InputError(f"cannot scale the circular feature {feature!r}; use with_counts to edit it")
        if not (np.isfinite(factor) and factor > 0):
            raise InputError(f"scale factor must be a finite number > 0, got {factor!r}")
        h = self.histograms[feature]
        edges = np.asarray(h.edges) * factor
        if feature == "dominance" and edges[-1] > 1:
            keep = edges[:-1] < 1
            edges = np.minimum(edges, 1.0)
            counts = np.asarray(h.counts)[keep]
            counts[-1] += np.asarray(h.counts)[~keep].sum()
            edges = np.append(edges[:-1][keep], 1.0)
            return self._edited(f"scale {feature} x{factor:g}", bands=None, histograms={
                **self.histograms, feature: FeatureHistogram(tuple(edges), tuple(counts), h.open_last)},
                **self._relief_after(feature))
        new = FeatureHistogram(tuple(float(v) for v in edges), h.counts, h.open_last)
        _check_range(feature, new)
        return self._edited(f"scale {feature} x{factor:g}", histograms={**self.histograms, feature: new},
                            **self._relief_after(feature))

    def shifted(self, feature: str, offset: float) -> "TerrainType":
        """New type with a linear feature's values shifted by ``offset`` (elevation: metres)."""
        _check_feature(feature)
        if FEATURES[feature][1] != "linear":
            raise InputError(f"cannot shift the circular feature {feature!r}; use with_counts to edit it")
        h = self.histograms[feature]
        new = FeatureHistogram(tuple(float(v) + float(offset) for v in h.edges), h.counts, h.open_last)
        _check_range(feature, new)
        if feature == "elevation":  # a shift keeps every gradient and ridge slope
            return self._edited(f"shift {feature} {offset:+g}", histograms={**self.histograms, feature: new})
        return self._edited(f"shift {feature} {offset:+g}", histograms={**self.histograms, feature: new},
                            **self._relief_after(feature))

    def _relief_after(self, feature: str) -> dict[str, Any]:
        """The gradient and ridge-slope records after an edit of ``feature`` (dropped when they no longer hold)."""
        drop_gradient = feature in ("elevation", "isolation_distance")
        keep_slope = FEATURES[feature][1] != "linear"  # only the direction histograms leave it as it is
        return {"gradient": None if drop_gradient else self.gradient,
                "neighbour_gradient": None if drop_gradient else self.neighbour_gradient,
                "max_ridge_slope": self.max_ridge_slope if keep_slope else None,
                "saddle_level": self.saddle_level if keep_slope else None,
                "forced_tail": self.forced_tail if keep_slope else None,
                "plain_dominance": self.plain_dominance if keep_slope else None}

    def with_density(self, peak_density_per_km2: float) -> "TerrainType":
        return self._edited(f"density {peak_density_per_km2:g}", peak_density_per_km2=float(peak_density_per_km2),
                            neighbour_gradient=None, max_ridge_slope=None, saddle_level=None, forced_tail=None,
                            plain_dominance=None)

    def with_rho(self, rho: float) -> "TerrainType":
        return self._edited(f"rho {rho:g}", rho=float(rho))

    # ------------------------------------------------------------------- I/O
    def to_dict(self) -> dict[str, Any]:
        return {
            "format": TYPE_FORMAT,
            "version": TYPE_VERSION,
            "name": self.name,
            "units": {k: u for k, (u, _) in FEATURES.items()},
            "peak_density_per_km2": float(self.peak_density_per_km2),
            "rho": float(self.rho),
            "min_prominence_m": float(self.min_prominence_m),
            "isolation_basis": self.isolation_basis,
            "histograms": {k: self.histograms[k].to_dict() for k in FEATURES},
            "provenance": dict(self.provenance),
            "bands": None if self.bands is None else {k: v for k, v in self.bands.items()},
            "source_crs": self.source_crs,
            "source_center": None if self.source_center is None else list(self.source_center),
            "texture": None if self.texture is None else dict(self.texture),
            "disks": None if self.disks is None else dict(self.disks),
            "gradient": None if self.gradient is None else self.gradient.to_dict(),
            "ridge_contrast": self.ridge_contrast,
            "neighbour_gradient": self.neighbour_gradient,
            "max_ridge_slope": self.max_ridge_slope,
            "saddle_level": self.saddle_level,
            "forced_tail": self.forced_tail,
            "plain_dominance": None if self.plain_dominance is None else self.plain_dominance.to_dict(),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, source: str = "terrain type") -> "TerrainType":
        if not isinstance(data, Mapping) or data.get("format") != TYPE_FORMAT:
            raise SchemaError(f"{source} is not an orokit terrain type (format {data.get('format') if isinstance(data, Mapping) else None!r}, "
                              f"expected {TYPE_FORMAT!r}); create one with `orokit type`")
        ver = data.get("version")
        if ver != TYPE_VERSION:
            raise SchemaError(f"{source} has terrain-type version {ver!r}; this orokit reads version {TYPE_VERSION}. "
                              "Re-create it with `orokit type` from the same analysis")
        factors = _unit_factors(data.get("units"), source)
        try:
            hists = {k: FeatureHistogram(tuple(float(e) * factors.get(k, 1.0) for e in v["edges"]),
                                         tuple(v["counts"]), bool(v.get("open_last", False)))
                     for k, v in data["histograms"].items() if k in FEATURES}
            return cls(str(data["name"]), hists, float(data["peak_density_per_km2"]), float(data["rho"]),
                       float(data["min_prominence_m"]), str(data.get("isolation_basis", "peaks")),
                       dict(data.get("provenance", {})), data.get("bands"),
                       source_crs=data.get("source_crs"),
                       source_center=None if data.get("source_center") is None else tuple(data["source_center"]),
                       texture=data.get("texture"), disks=data.get("disks"),
                       gradient=_optional_histogram(data.get("gradient")),
                       ridge_contrast=data.get("ridge_contrast"),
                       neighbour_gradient=data.get("neighbour_gradient"), max_ridge_slope=data.get("max_ridge_slope"),
                       saddle_level=data.get("saddle_level"), forced_tail=data.get("forced_tail"),
                       plain_dominance=_optional_histogram(data.get("plain_dominance")))
        except (KeyError, TypeError, ValueError) as exc:
            if isinstance(exc, SchemaError):
                raise
            raise SchemaError(f"{source}: malformed terrain type ({type(exc).__name__}: {exc})") from exc

    def save(self, path: PathLike) -> Path:
        """Write the type as JSON (atomically)."""
        from orokit.io.atomic import write_text_atomic

        return write_text_atomic(path, json.dumps(self.to_dict(), indent=1))

    @classmethod
    def load(cls, path: PathLike) -> "TerrainType":
        return load_terrain_type(path)


#: accepted unit names per kind of feature -> factor to the unit of FEATURES
_LENGTH_UNITS = {"m": 1.0, "km": 1000.0}
_DIRECTION_UNITS = {"deg": 1.0, "degree": 1.0, "degrees": 1.0}
_RATIO_UNITS = {"1": 1.0, "": 1.0, "ratio": 1.0, "fraction": 1.0}


def _unit_factors(units: Any, source: str) -> dict[str, float]:
    """Factors that bring each histogram's edges to the units of :data:`FEATURES`.

    A type without ``units`` is in those units (metres, degrees). Elevation and
    prominence may be ``"ft"`` (x 0.3048) or ``"us-ft"``, lengths also ``"km"``.
    """
    from orokit.errors import UnitsError
    from orokit.io._units import factor_to_metres

    if units is None:
        return {}
    if not isinstance(units, Mapping):
        raise SchemaError(f"{source}: 'units' must map features to units, e.g. {{\"elevation\": \"m\"}}; "
                          f"got {units!r}")
    factors: dict[str, float] = {}
    for feature, unit in units.items():
        if feature not in FEATURES:
            raise SchemaError(f"{source}: 'units' names an unknown feature {feature!r}; features: {list(FEATURES)}")
        want, _ = FEATURES[feature]
        key = str(unit).strip().lower()
        if want == "m":
            if key in _LENGTH_UNITS:
                factors[feature] = _LENGTH_UNITS[key]
                continue
            try:
                factors[feature] = factor_to_metres(key)
            except UnitsError:
                raise SchemaError(f"{source}: unknown unit {unit!r} for {feature}; use 'm', 'km', 'ft' or 'us-ft'") \
                    from None
        elif want == "deg":
            if key not in _DIRECTION_UNITS:
                raise SchemaError(f"{source}: unit {unit!r} for {feature}; directions are in 'deg' "
                                  "(counter-clockwise from east)")
        elif key not in _RATIO_UNITS:
            raise SchemaError(f"{source}: unit {unit!r} for {feature}; {feature} is a ratio in [0, 1] (unit '1')")
    return factors


def load_terrain_type(path: PathLike) -> TerrainType:
    """Read a type JSON written by :meth:`TerrainType.save`.

    Raises
    ------
    SchemaError
        Not a type file, another format version, or malformed histograms.
    """
    from orokit.io.files import read_input_bytes

    raw = read_input_bytes(path, what="terrain type file", fix="give the JSON file written by `orokit type`")
    return loads_terrain_type(raw, source=str(path))


def loads_terrain_type(text: bytes | str, *, source: str = "terrain type") -> TerrainType:
    """Parse the JSON text of a terrain type (see :func:`load_terrain_type`).

    Raises
    ------
    SchemaError
        Not JSON, not a type, another version, malformed or inconsistent content.
    """
    try:
        data = json.loads(text)
    except (json.JSONDecodeError, UnicodeDecodeError, RecursionError) as exc:
        raise SchemaError(f"{source} is not valid JSON ({exc}); is it a terrain type written by `orokit type`?") \
            from None
    return TerrainType.from_dict(data, source=source)


def _check_feature(feature: str) -> None:
    if feature not in FEATURES:
        raise InputError(f"unknown feature {feature!r}; choose one of {list(FEATURES)}")


def _check_range(feature: str, h: FeatureHistogram) -> None:
    e = np.asarray(h.edges)
    if feature == "dominance" and (e[0] < 0 or e[-1] > 1):
        raise SchemaError(f"dominance histogram must lie in [0, 1], got edges {e[0]:g}..{e[-1]:g}")
    if feature == "elevation" and e[-1] <= 0:
        raise SchemaError(f"elevation histogram must reach above 0 m, got edges {e[0]:g}..{e[-1]:g}")
    if feature in ("prominence", "isolation_distance", "saddle_distance") and e[0] < 0:
        raise SchemaError(f"{feature} histogram must not go below 0, got first edge {e[0]:g}")
    if FEATURES[feature][1] == "circular" and (e[0] < 0 or e[-1] > 360):
        raise SchemaError(f"{feature} histogram must lie in [0, 360] degrees")


def _disk_record(x: np.ndarray, y: np.ndarray, z: np.ndarray, prom: np.ndarray, crs: Any,
                 extent: tuple[float, float, float, float] | None, min_prominence_m: float) -> dict[str, Any] | None:
    """The ``disks`` record of a type (None when the data holds no 10 km disk)."""
    from orokit.synthesis.disks import (border_density, border_rank, disk_quantiles, disk_statistics,
                                        level_quantiles)
    from orokit.synthesis.orometry import planar_xy

    if extent is None:
        ex = np.array([np.nanmin(x), np.nanmax(x)])
        ey = np.array([np.nanmin(y), np.nanmax(y)])
    else:
        ex = np.array([extent[0], extent[2]], float)
        ey = np.array([extent[1], extent[3]], float)
    cx, cy = np.meshgrid(ex, ey)
    px, py = planar_xy(np.concatenate([x, cx.ravel()]), np.concatenate([y, cy.ravel()]), crs)
    k = x.size
    box = (float(px[k:].min()), float(py[k:].min()), float(px[k:].max()), float(py[k:].max()))
    stats = disk_statistics(px[:k], py[:k], z, prom, box, min_prominence_m=min_prominence_m)
    rec = disk_quantiles(stats)
    if rec is not None:
        rec["border_rank"] = border_rank(px[:k], py[:k], z, box)
        rec["border_density"] = border_density(px[:k], py[:k], box)
        rec["median_rank"] = level_quantiles(stats["median_rank"])
        rec["peak_relief_m"] = level_quantiles(stats["peak_relief_m"])
    return rec


def tree_ridge_contrast(tree: Any, min_prominence_m: float = 30.0) -> float | None:
    """:func:`orokit.synthesis.ridges.ridge_contrast` of a Divide Tree pruned at ``min_prominence_m``
    (planar metres; None below 4 peaks or when undefined)."""
    from orokit.synthesis.orometry import planar_xy
    from orokit.synthesis.ridges import ridge_contrast

    tree = tree.prune(min_prominence_m) if min_prominence_m > 0 else tree
    if tree.n_peaks < 4:
        return None
    x, y = planar_xy(tree.peaks["x"].to_numpy(float), tree.peaks["y"].to_numpy(float), tree.crs)
    c = ridge_contrast(x, y, tree.peaks["elevation"].to_numpy(float), tree.edges["peak_a"].to_numpy(np.int64),
                       tree.edges["peak_b"].to_numpy(np.int64))
    return c if np.isfinite(c) else None


def tree_max_ridge_slope(tree: Any, min_prominence_m: float = 30.0, quantile: float = 0.99) -> float | None:
    """``quantile`` of ``(h_a + h_b - 2 s) / |AB|`` over the ridges of a Divide Tree pruned at
    ``min_prominence_m`` (planar metres; None below 4 peaks or when undefined)."""
    from orokit.synthesis.orometry import planar_xy

    tree = tree.prune(min_prominence_m) if min_prominence_m > 0 else tree
    if tree.n_peaks < 4:
        return None
    x, y = planar_xy(tree.peaks["x"].to_numpy(float), tree.peaks["y"].to_numpy(float), tree.crs)
    z = tree.peaks["elevation"].to_numpy(float)
    a, b = tree.edges["peak_a"].to_numpy(np.int64), tree.edges["peak_b"].to_numpy(np.int64)
    s = tree.saddles["elevation"].to_numpy(float)[tree.edges["saddle"].to_numpy(np.int64)]
    length = np.hypot(x[a] - x[b], y[a] - y[b])
    ok = length > 0
    if not ok.any():
        return None
    v = float(np.quantile((z[a] + z[b] - 2 * s)[ok] / length[ok], quantile))
    return v if np.isfinite(v) and v >= 0 else None


def tree_saddle_level(tree: Any, min_prominence_m: float = 30.0, k: int = 16) -> float | None:
    """:func:`orokit.synthesis.saddles.saddle_level` of a Divide Tree pruned at ``min_prominence_m`` (planar
    metres; None below 4 peaks or when undefined)."""
    from orokit.synthesis.saddles import saddle_level

    arrays = _planar_tree(tree, min_prominence_m)
    if arrays is None:
        return None
    v = saddle_level(*arrays, k=k)
    return v if np.isfinite(v) and 0 <= v <= 1 else None


def _planar_tree(tree: Any, min_prominence_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                                               np.ndarray] | None:
    """A Divide Tree pruned at ``min_prominence_m`` as arrays ``z, x, y, a, b, s`` (planar metres; saddle elevation
    per ridge), or None below 4 peaks."""
    from orokit.synthesis.orometry import planar_xy

    tree = tree.prune(min_prominence_m) if min_prominence_m > 0 else tree
    if tree.n_peaks < 4:
        return None
    x, y = planar_xy(tree.peaks["x"].to_numpy(float), tree.peaks["y"].to_numpy(float), tree.crs)
    s = tree.saddles["elevation"].to_numpy(float)[tree.edges["saddle"].to_numpy(np.int64)]
    return (tree.peaks["elevation"].to_numpy(float), x, y, tree.edges["peak_a"].to_numpy(np.int64),
            tree.edges["peak_b"].to_numpy(np.int64), s)


def tree_forced_tail(tree: Any, min_prominence_m: float = 30.0, quantile: float = 0.9) -> float | None:
    """:func:`orokit.synthesis.saddles.forced_tail` of a Divide Tree pruned at ``min_prominence_m``, at the
    ``quantile`` of its keyed peaks' prominences (None below 4 peaks)."""
    from orokit.synthesis.saddles import forced_tail

    tree = tree.prune(min_prominence_m) if min_prominence_m > 0 else tree
    if tree.n_peaks < 4:
        return None
    pt = tree.prominence_table()
    prom = pt["prominence"].to_numpy(float)[pt["key_saddle"].to_numpy() >= 0]
    if prom.size == 0:
        return None
    v = forced_tail(tree.peaks["elevation"].to_numpy(float), tree.edges["peak_a"].to_numpy(np.int64),
                    tree.edges["peak_b"].to_numpy(np.int64), float(np.quantile(prom, quantile)))
    return v if np.isfinite(v) else None


def tree_plain_dominance(tree: Any, min_prominence_m: float = 30.0, k: int = 16) -> FeatureHistogram | None:
    """Histogram (40 bins on [0, 1]) of :func:`orokit.synthesis.saddles.plain_dominance` over the peaks of a
    Divide Tree pruned at ``min_prominence_m`` (planar metres; None below 4 peaks)."""
    from orokit.synthesis.saddles import plain_dominance

    arrays = _planar_tree(tree, min_prominence_m)
    if arrays is None:
        return None
    v = plain_dominance(*arrays, k=k)
    v = v[np.isfinite(v)]
    if v.size < 2:
        return None
    return FeatureHistogram.from_values(v, np.linspace(0.0, 1.0, N_LINEAR_BINS + 1))


def _optional_histogram(data: Any) -> FeatureHistogram | None:
    """A :class:`FeatureHistogram` from its ``to_dict`` form (None stays None)."""
    if data is None:
        return None
    return FeatureHistogram(tuple(float(e) for e in data["edges"]), tuple(data["counts"]),
                            bool(data.get("open_last", False)))


def _neighbour_gradient(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> float | None:
    """Median ``|h_p - h_q| / d(p, q)`` from every peak to its nearest peak (planar metres)."""
    from orokit.synthesis.orometry import neighbour_gradients

    g = neighbour_gradients(x, y, z)
    return float(np.median(g)) if g.size else None


def estimate_rho(tree: Any, min_prominence_m: float = 30.0, choices: tuple[float, ...] = (0.0, 1.0, 2.0)) -> float:
    """Ridge exponent whose Delaunay MST best reproduces the ridges of ``tree``.

    For each candidate rho the MST of the Delaunay triangulation of the peaks is
    built with weight ``|Pi - Pj| / min(h_i, h_j) ** rho``; the rho sharing the most
    peak-to-peak edges with the real tree wins (ties: the smaller rho).
    """
    from orokit.synthesis.ridges import delaunay_mst

    tree = tree.prune(min_prominence_m) if min_prominence_m > 0 else tree
    if tree.n_peaks < 4:
        return 1.0
    from orokit.synthesis.orometry import planar_xy

    x, y = planar_xy(tree.peaks["x"].to_numpy(float), tree.peaks["y"].to_numpy(float), tree.crs)
    z = tree.peaks["elevation"].to_numpy(float)
    real = {(min(a, b), max(a, b)) for a, b in zip(tree.edges["peak_a"], tree.edges["peak_b"])}
    best, best_score = 1.0, -1
    for rho in choices:
        a, b = delaunay_mst(x, y, z, rho=rho)
        score = len(real & {(min(i, j), max(i, j)) for i, j in zip(a.tolist(), b.tolist())})
        logger.debug("rho=%g shares %d of %d ridges", rho, score, len(real))
        if score > best_score:
            best, best_score = rho, score
    return float(best)


def _check_bands(bands: Mapping[str, Any], hists: Mapping[str, FeatureHistogram]) -> None:
    try:
        idx = [int(v) for v in bands["elevation_bins"]]
        prom = np.asarray(bands["prominence"], float)
        dom = np.asarray(bands["dominance"], float)
    except (KeyError, TypeError, ValueError) as exc:
        raise SchemaError(f"malformed elevation bands: {exc}") from exc
    k = len(idx) - 1
    ok = (
        k >= 1 and idx[0] == 0 and idx[-1] == hists["elevation"].n_bins and all(np.diff(idx) > 0)
        and prom.shape == (k, hists["prominence"].n_bins) and dom.shape == (k, hists["dominance"].n_bins)
        and np.all(prom >= 0) and np.all(dom >= 0) and np.all(prom.sum(axis=1) > 0) and np.all(dom.sum(axis=1) > 0)
    )
    if not ok:
        raise SchemaError("elevation bands do not fit the elevation/prominence/dominance histograms "
                          "(bin indices or count shapes); re-create the type with `orokit type`")


def _elevation_bands(z: np.ndarray, prom: np.ndarray, dom: np.ndarray, hists: Mapping[str, FeatureHistogram],
                     *, n_bands: int = 8, min_count: int = 30) -> dict[str, Any] | None:
    """Prominence/dominance counts per elevation band (quantile groups of elevation bins)."""
    he = hists["elevation"]
    zb = np.clip(he.bin_index(z), 0, he.n_bins - 1)
    per_bin = np.bincount(zb, minlength=he.n_bins)
    k = int(min(n_bands, per_bin.sum() // max(min_count, 1)))
    if k < 2:
        return None
    cum = np.cumsum(per_bin)
    cuts = sorted({int(np.searchsorted(cum, per_bin.sum() * q / k, side="left")) + 1 for q in range(1, k)})
    idx = [0] + [c for c in cuts if 0 < c < he.n_bins] + [he.n_bins]
    idx = sorted(set(idx))
    band = np.searchsorted(np.asarray(idx[1:-1]), zb, side="right")
    ph, dh = hists["prominence"], hists["dominance"]
    prom_c, dom_c = [], []
    for b in range(len(idx) - 1):
        m = band == b
        pi, di = ph.bin_index(prom[m]), dh.bin_index(dom[m])
        prom_c.append(np.bincount(pi[pi >= 0], minlength=ph.n_bins).astype(float).tolist())
        dom_c.append(np.bincount(di[di >= 0], minlength=dh.n_bins).astype(float).tolist())
    if any(sum(c) == 0 for c in prom_c) or any(sum(c) == 0 for c in dom_c):
        return None
    return {"elevation_bins": idx, "prominence": prom_c, "dominance": dom_c}


def band_histograms(tt: TerrainType) -> tuple[np.ndarray, list[FeatureHistogram], list[FeatureHistogram]]:
    """Elevation edges of the bands and per-band prominence and dominance histograms.

    A type without bands gives one band with the marginal histograms.
    """
    he = tt.histograms["elevation"]
    e = np.asarray(he.edges, float)
    if tt.bands is None:
        return np.array([e[0], e[-1]]), [tt.histograms["prominence"]], [tt.histograms["dominance"]]
    idx = list(tt.bands["elevation_bins"])
    ph, dh = tt.histograms["prominence"], tt.histograms["dominance"]
    prom = [FeatureHistogram(ph.edges, tuple(float(c) for c in row), ph.open_last) for row in tt.bands["prominence"]]
    dom = [FeatureHistogram(dh.edges, tuple(float(c) for c in row), dh.open_last) for row in tt.bands["dominance"]]
    return e[idx], prom, dom


def source_location(crs: Any, x: float, y: float) -> tuple[str | None, tuple[float, float] | None]:
    """``(WKT, (lon, lat))`` of the point ``(x, y)`` in ``crs``; ``(None, None)`` without a CRS.

    >>> wkt, (lon, lat) = source_location("EPSG:32633", 500000.0, 0.0)
    >>> wkt.startswith("PROJCRS"), round(lon, 6), round(lat, 6)
    (True, 15.0, 0.0)
    """
    if crs is None:
        return None, None
    from pyproj import CRS, Transformer

    c = CRS.from_user_input(crs)
    if c.is_geographic:
        lon, lat = float(x), float(y)
    else:
        lon, lat = Transformer.from_crs(c, "EPSG:4326", always_xy=True).transform(float(x), float(y))
    if not (np.isfinite(lon) and np.isfinite(lat)):
        return c.to_wkt(), None
    return c.to_wkt(), (float(lon), float(lat))
