"""Divide Tree synthesis from terrain types (Argudo et al. 2019, section 5).

:func:`synthesize_divide_tree` turns one or several :class:`TerrainType` (mixed by a
type map) into a new, georeferenced :class:`DivideTree`: peaks by multi-pass dart
throwing, ridges by a Delaunay minimum spanning tree, saddle elevations by
alternating optimal transport of dominance and prominence, and saddle positions that
follow the key-saddle distance and direction histograms.
"""
from __future__ import annotations

import copy
import logging
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any, Literal

import numpy as np
import pandas as pd

from orokit._typing import SeedLike
from orokit.errors import InputError, OrokitError, OrokitWarning
from orokit.synthesis.controls import Domain, build_controls, make_domain
from orokit.synthesis.terrain_type import TerrainType
from orokit.topology.divide_tree import DivideTree
from orokit.topology.tables import NONE_ID, validate_peak_table

logger = logging.getLogger(__name__)

__all__ = ["synthesize_divide_tree", "SynthesisParams", "peaks_table", "MAX_PEAKS"]

#: refuse to synthesize more peaks than this (the arrays of the dart throwing and the
#: optimal transport grow faster than linearly; real 90 km regions hold a few thousand)
MAX_PEAKS = 1_000_000


def _fixed_frame(fixed_peaks: Any) -> pd.DataFrame:
    if fixed_peaks is None:
        return pd.DataFrame({"x": [], "y": [], "elevation": []})
    if isinstance(fixed_peaks, np.ndarray):
        arr = np.asarray(fixed_peaks, float).reshape(-1, 3)
        return pd.DataFrame(arr, columns=["x", "y", "elevation"])
    frame = pd.DataFrame(fixed_peaks)
    if "geometry" in frame.columns and not {"x", "y"} <= set(frame.columns):
        frame["x"] = [g.x for g in frame["geometry"]]
        frame["y"] = [g.y for g in frame["geometry"]]
    miss = {"x", "y", "elevation"} - set(frame.columns)
    if miss:
        raise InputError(f"fixed peaks lack columns {sorted(miss)}; give x, y (output CRS metres) and elevation (m)")
    return frame[["x", "y", "elevation"]].astype(float).reset_index(drop=True)


def _check_fixed(frame: pd.DataFrame, source: str) -> None:
    """Refuse fixed peaks that cannot be in a Divide Tree, before anything is computed.

    Rows are quoted 1-based, as in the file (data rows, the header not counted).
    """
    xyz = frame[["x", "y", "elevation"]].to_numpy(float)
    for j, col in enumerate(("x", "y", "elevation")):
        bad = np.flatnonzero(~np.isfinite(xyz[:, j]))
        if bad.size:
            rows = ", ".join(str(i + 1) for i in bad[:5]) + (", ..." if bad.size > 5 else "")
            raise InputError(f"{source}: {bad.size} fixed peak(s) have no valid {col} (NaN or infinite) at data "
                             f"row(s) {rows}; give every fixed peak x, y and elevation (m > 0)")
    bad = np.flatnonzero(xyz[:, 2] <= 0)
    if bad.size:
        raise InputError(f"{source}: fixed peak at data row {bad[0] + 1} has elevation {xyz[bad[0], 2]:g} m; "
                         "fixed peaks need elevations > 0 m")
    if len(xyz) > 1:
        order = np.lexsort((xyz[:, 1], xyz[:, 0]))
        same = np.flatnonzero((np.diff(xyz[order, 0]) == 0) & (np.diff(xyz[order, 1]) == 0))
        if same.size:
            i, j = sorted((int(order[same[0]]), int(order[same[0] + 1])))
            raise InputError(f"{source}: fixed peaks at data rows {i + 1} and {j + 1} share the position "
                             f"({xyz[i, 0]:g}, {xyz[i, 1]:g}); two peaks cannot stand on one point (the tree would "
                             "split into a forest). Remove or move one of them.")


@dataclass(frozen=True)
class SynthesisParams:
    """Parameters of :func:`synthesize_divide_tree` (how to synthesize, not what).

    n_passes : multi-pass count (each pass holds twice as many peaks as the previous).
    n_candidates : dart candidates per peak.
    max_ot_iterations : bound on the alternating dominance / prominence rounds.
    saddle_placement : "targeted" (key-saddle distance and direction follow the
        type) or "paper" (random split point with a small perpendicular jitter).
    grid_cells : cells along the longer side of the control grid.
    auto_elevation_m : without a C_H, use a smooth random C_H with this correlation
        length (metres) following the elevation histogram, so peak elevations are
        spatially correlated as in real ranges (None: no C_H term). Default 4 km (8 km until
        session 6; see ``follow_gradient`` for what it changed).
    use_bands : draw prominence/dominance targets per elevation band of the type
        (True), from its marginal histograms (False), or "auto": run both and keep the
        saddles whose dominance and prominence histograms match the type better.
    void_weight : between dart-throwing passes, lower peaks are drawn to the holes left by
        the earlier ones with this weight (:func:`orokit.synthesis.darts.void_density`;
        0 = the paper's ridge density only). 1.0 from issue 11 until session 17: the 90th percentile of
        the distance to the nearest peak went from 1.54 to 1.18 x the real trees', and the twins'
        10 km disks were classified right more often (``benchmarks/realism.py``, 6 tuning regions:
        alaska 61 -> 82 %, himalaya-everest 55 -> 65 %, norway 61 -> 72 %, the others equal) with
        the same landform statistics within target. Default 3 since session 17, with ``border_density``,
        ``valley_network`` 0.7, ``follow_ridge_slope``, ``follow_neighbour_gradient`` and ``gradient_tail`` 2
        (issue 11: ``benchmarks/realism.py --twin-only``, 13 regions, seeds 0 / 1 / 2, session 17: the twins'
        disks reclassified in 10 / 9 / 11 of 12 regions against the session-16 defaults' 8 / 9 / 9, vote 12
        each, within all six tune 3 / 3 / 3 and held out 3 / 4 / 3 against 2 / 2 / 3 and 2 / 3 / 1; the tune
        mean distance / target rises, 0.654 / 0.653 / 0.713 -> 0.786 / 0.718 / 0.736; see NOTES, twins16-17).
    disk_weight : strength of the per-disk target in the dart throwing: the share of 10 km
        disks that hold one of the highest peaks follows the type's ``disks`` record
        (:mod:`orokit.synthesis.disks`; 0 or a type without it: off). Without it the highest
        peaks, pushed apart by their large isolation, end up along the domain border. Default 32
        (issue 11, ``benchmarks/realism.py``, 6 tuning regions, seeds 0-2): the Wasserstein
        distance of the per-disk ``top_rank`` to the real DEM's went from 0.14-0.27 to 0.02-0.09
        (seed 2), twin disks right 87.2 % on average against 84.6 % with 0, landforms equal.
    disk_count_weight : strength of the per-disk peak count target in the dart throwing: every 10 km
        disk centre draws a target count from the type's ``disks`` record (its ``peaks`` quantiles,
        a smooth random field mapped by rank) and each peak's candidates are weighted towards the
        disks short of their share (:func:`orokit.synthesis.darts.disk_count_targets`; 0 or a type
        without the record: off). An option, off (issue 11, session 14: see NOTES).
    border_trend : the automatic C_H follows the type's ``border_rank`` (mean elevation rank of
        its peaks by distance to the data border, in its ``disks`` record), so the twin of a DEM
        cropped around its relief holds its highest peaks inside as the DEM does; without it
        (False, or a type without the record) the C_H is stationary and where the highest peaks
        land is one random draw (issue 11). Default True (``benchmarks/realism.py``, 6 tuning
        regions, seed 0): share of the twin's highest 2 % of peaks >= 10 km inside the border
        0.08-0.67 -> 0.33-1.00 against the real 0.11-1.00, TV distance of the disks' relative
        elevation 0.13-0.46 -> 0.06-0.45, landforms within target equal.
    border_density : without a user C_P (and with one type), the density map follows the type's
        ``border_density`` (relative peak density by distance to the data border, in its ``disks``
        record; :func:`orokit.synthesis.controls.border_density_map`), and the automatic C_H is ranked
        by it, so the twin of a DEM cropped around its relief holds as many of its peaks inside as the
        DEM does (off, or a type without the record: a uniform C_P). The profile is first shrunk towards 1
        by its sampling noise (:func:`orokit.synthesis.disks.shrink_border_density`; session 16, after
        session 15's runs: andes-chile's 149 peaks gave +-18 % per band). Default True since session 17 (with
        the other session-17 defaults, see ``void_weight``; alone in session 15: reclassification 10 / 9 / 7 of 12
        in seeds 0-2 with karakoram's vote wrong in seed 2; see NOTES).
    valley_network : weight v in [0, 1] of a folded noise in the automatic C_H: its smooth noise becomes
        ``(1 - v) g + v |h|`` (:func:`orokit.synthesis.controls.random_elevation_fields`), so the low
        peaks, and the valleys the renderer cuts between them, follow the zero lines of h, a network
        crossing the domain, instead of a few isolated basins (0: no network, nothing more drawn). Default
        0.7 since session 17 (issue 11, with the other session-17 defaults, see ``void_weight``; NOTES).
    elevation_tolerance : width of the C_H acceptance of the dart throwing, as a share of the C_H
        range (the paper: 1/20). Default 0.0125 (issue 11): with 0.05 neighbouring twin peaks differed
        twice as much in elevation as real ones (median |dz| / distance to the nearest peak 0.23-0.24
        against 0.11-0.12, 90th percentile 0.85-0.95 against 0.29-0.35; alaska, himalaya-everest, seed 0),
        which made the ridges, and the flanks the renderer hangs on them, too steep; 0.0125 gives
        0.09-0.10 / 0.32-0.33 with the histograms as well matched.
    saddle_slope_ratio : a saddle sits where neither half of its ridge falls more than this times as
        steeply as at the even split (where both halves fall at one slope); None: the key-saddle
        distance alone decides, which squeezed saddles against a peak (half-ridge slopes, 90th
        percentile 1.28-1.43 against 0.50-0.57 in the real trees; with 1.5: 0.49-0.58). Default 1.5
        (issue 11; ``benchmarks/realism.py``, seed 0, both changes: twins' vote right for 12 of the 12
        regions the model knows instead of 10, peaks recovered >= 99.1 %).
    follow_gradient : the dart throwing also follows the type's ``gradient`` histogram (elevation
        gradient from a peak to its nearest higher peak, demand feedback as for the isolation
        histograms; off for a type without it). Default True (issue 11, session 7).
    follow_ridge_contrast : the ridges' MST weight favours steep edges just enough that the tree's
        :func:`~orokit.synthesis.ridges.ridge_contrast` matches the type's (off for a type without
        it; with several types, their mean weighted by peak count). Default True (issue 11, session 8;
        ``benchmarks/realism.py --twin-only``, 13 regions, seeds 0-2, load 9-16): landform checks met
        88 / 88 of 108 on the tuning group and 88 / 86 of 126 held out (on / off), mean distance over
        target 0.69 / 0.72 and 0.78 / 0.81, slope, curvature and 1 km relief distances lower in 9, 11
        and 11 of 13 regions (3-seed means); reclassification 9, 9, 10 / 10, 9, 9 of 12, vote 12 of 12.
    follow_ridge_slope : no saddle is lowered below ``(h_a + h_b - m |AB|) / 2`` with m the type's
        ``max_ridge_slope`` (the 99th percentile of its tree's ridge slopes; off for a type without it,
        with several types their largest), so a deep saddle needs a long ridge (issue 11, session 9: the
        twins' 99th percentile ridge slope was 1.2-1.6 x the real trees' in steep regions, short ridges
        with deep saddles). Default True since session 17 (see ``void_weight``; NOTES, sessions 9-17).
    follow_neighbour_gradient : the automatic C_H gets a component of correlation ``fine_elevation_m``
        whose weight (:data:`FINE_WEIGHTS`, the first reaching it) brings the median elevation gradient
        between neighbouring peaks to the type's ``neighbour_gradient`` (off for a type without it, with
        a user C_H or several types). The dart throwing runs once per weight tried, with the same draws
        (issue 11, session 9: with the 4 km C_H and its tight tolerance neighbouring twin peaks were too
        alike, rockies 0.05 against 0.10). Default True since session 17 (see ``void_weight``; NOTES).
    fine_elevation_m : correlation length of that component (metres, default 1 km: the spacing of
        neighbouring peaks).
    ridge_slope_factor : ``follow_ridge_slope`` bounds the ridge slopes by this times the type's
        ``max_ridge_slope`` (default 1; > 1 lets a few ridges be steeper than the real tree's 99th
        percentile, as in the real tree's top 1 %).
    gradient_tail : ``follow_gradient`` closes the open last bin of the type's gradient histogram
        (from its 99th percentile up) at this times its lower edge, so the 1 % of steepest peaks
        cannot be arbitrarily steep (None: open). Session 11: with the fine component (alaska, seed 0)
        1.9 % of the twin's peaks lay above the real 99th percentile and 0.7 % above twice it
        (max 3.4 against 0.70; without the component 0.3 % / 0 %). Default 2 since session 17 (see
        ``void_weight``).
    fine_needs_reach : ``follow_neighbour_gradient`` keeps no fine component when even the largest of
        :data:`FINE_WEIGHTS` leaves the median below the type's (a deficit the 1 km scale does not
        explain: gobi and sahara, where the largest weight only bent the elevation distribution,
        gobi's hypsometry distance 0.022 -> 0.082 at weight 3; session 11). False: the closer of the
        last two weights, as before.
    saddle_level_weight : weight w of a level term in the saddle OT's cost, ``w (s - m)^2 / |AB|`` with ``m`` the
        median of the saddles of the 16 nearest ridges (:func:`orokit.synthesis.saddles.assign_saddle_elevations`):
        the prominence targets go to the peaks standing as far above their neighbours' saddles (0: the paper's cost).
    follow_saddle_level : the level term's weight is the first of :data:`SADDLE_LEVEL_WEIGHTS` (from
        ``saddle_level_weight``) whose tree has :func:`~orokit.synthesis.saddles.saddle_level` no higher than the
        type's ``saddle_level``, or the one before it if that came closer (off, with an
        :class:`~orokit.errors.OrokitWarning`, for a type without it or with several types). An option, off
        (issue 11, session 17: see NOTES).
    follow_disk_rank : the placement made without the option is judged by its 10 km disks
        (:func:`disk_rank_margins`: their ``median_rank`` quantiles no lower than the type's at
        :data:`DISK_RANK_LEVELS` and no higher at :data:`DISK_RANK_HIGH_LEVELS`, their ``peak_relief_m`` no higher
        at the high levels, when the type records it); when it lies outside by more than ``disk_rank_tolerance``,
        the automatic C_H is redrawn and the peaks thrown again (new noises and draws each, up to
        ``disk_rank_draws`` placements in all) and the first inside is kept (else the one outside by least), so
        the lowest peaks do not gather in a basin wider than any of the source's lowest 10 km neighbourhoods, nor
        does every disk reach down into a valley (off, with an :class:`~orokit.errors.OrokitWarning`, for a type
        without the record, with a user C_H or several types). An option, off (issue 11, sessions 18-19: a twin
        disk far lower than every real disk was what rockies' and andes-aconcagua's missed disks had in common;
        see NOTES).
    disk_rank_draws : at most this many placements for ``follow_disk_rank`` (>= 1; 1: never redrawn).
    disk_rank_tolerance : how far outside the type's span (rank, or share of the type's relief) a placement may
        lie and still be kept by ``follow_disk_rank`` (>= 0).
    follow_forced_tail : the ridges' exponent rho is raised by the steps of :data:`FORCED_TAIL_RHO_STEPS`, each
        MST fitted to the ridge contrast again, until the tree's :func:`~orokit.synthesis.saddles.forced_tail`
        at the type's 90th-percentile prominence is no larger than the type's ``forced_tail`` (or the step that
        came closest), so the high peaks are joined along high ground as in the source (off, with an
        :class:`~orokit.errors.OrokitWarning`, for a type without the record or with several types). An
        option, off (issue 11, session 19: see NOTES).
    forced_tail_placement : the dart throwing follows the type's ``forced_tail``: a candidate on a ridge of the
        earlier passes whose lower end stands the type's 90th-percentile prominence or more above the peak (it would
        split the ridge and force that prominence on the end) fills a tail whose share of the peaks is the type's,
        so once it is used each pass's lower peaks go beside the higher ones, on their flanks, rather than into the
        low gaps between them (:func:`orokit.synthesis.darts.place_peaks`; off, with an
        :class:`~orokit.errors.OrokitWarning`, for types without the record). An option, off (issue 11, session
        20: see NOTES).
    follow_plain_dominance : the saddle OT matches the type's ``plain_dominance`` histogram as a third feature
        beside dominance and prominence (:func:`orokit.synthesis.saddles.assign_saddle_elevations`): each
        peak's prominence over its height above the lowest saddle of the 16 nearest ridges, so a dune's key
        saddle lies on the plain as often as in the source (off, with an :class:`~orokit.errors.OrokitWarning`,
        for a type without the record). The plain step runs only in rounds where its max-bin error exceeds
        :data:`~orokit.synthesis.saddles.PLAIN_GATE` times the other two's, and keeps the saddles of peaks whose
        value already lies in its target's bin. An option, off (issue 11, session 19: sahara's twin tree 0.13 ->
        0.07-0.08 in W1 of the real tree's values, at a cost in prominence fidelity; see NOTES).
    Measured for ``follow_gradient`` and the 4 km ``auto_elevation_m`` (``benchmarks/realism.py
    --twin-only``, 13 regions, seeds 0-2, session 7, load 6-9): twins' disks classified as their own
    region at least as often as the real disks under the spatial hold-out in 10, 9, 10 of 12 regions
    (both off: 7, 8, 8; the gradient alone 9, 9, 9; the 4 km C_H alone 9, 10, 10), vote right 12 of
    12 each (both off: 12, 12, 11); twins within all six landform targets 3, 2, 3 of 6 tuning regions
    (off: 2, 2, 3) and 1, 1, 1 of 7 held out (off: 2, 1, 1): per statistic 88 against 88 checks met
    over the tuning group and seeds, 86 against 91 held out (1 km relief and hypsometry). The C_H
    tolerance still bounds the spread: the twins' median nearest-peak gradient stays low in norway,
    rockies and karakoram (0.05 / 0.05 / 0.10 against 0.08 / 0.10 / 0.14, seed 0).
    """

    n_passes: int = 4
    n_candidates: int = 96
    max_ot_iterations: int = 16
    saddle_placement: Literal["targeted", "paper"] = "targeted"
    grid_cells: int = 256
    auto_elevation_m: float | None = 4000.0
    use_bands: bool | Literal["auto"] = "auto"
    void_weight: float = 3.0
    disk_weight: float = 32.0
    disk_count_weight: float = 0.0
    border_trend: bool = True
    border_density: bool = True
    valley_network: float = 0.7
    elevation_tolerance: float = 0.0125
    saddle_slope_ratio: float | None = 1.5
    follow_gradient: bool = True
    follow_ridge_contrast: bool = True
    follow_ridge_slope: bool = True
    follow_neighbour_gradient: bool = True
    fine_elevation_m: float = 1000.0
    ridge_slope_factor: float = 1.0
    fine_needs_reach: bool = False
    gradient_tail: float | None = 2.0
    saddle_level_weight: float = 0.0
    follow_saddle_level: bool = False
    follow_disk_rank: bool = False
    disk_rank_draws: int = 8
    disk_rank_tolerance: float = 0.05
    follow_forced_tail: bool = False
    forced_tail_placement: bool = False
    follow_plain_dominance: bool = False

    def __post_init__(self) -> None:
        if self.use_bands not in ("auto", True, False):
            raise InputError(f"use_bands must be 'auto', True or False, got {self.use_bands!r}")
        for name in ("border_trend", "border_density", "follow_gradient", "follow_ridge_contrast", "follow_ridge_slope",
                     "follow_neighbour_gradient", "fine_needs_reach", "follow_saddle_level", "follow_disk_rank",
                     "follow_forced_tail", "forced_tail_placement", "follow_plain_dominance"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise InputError(f"{name} must be True or False, got {getattr(self, name)!r}")
        if self.saddle_placement not in ("targeted", "paper"):
            raise InputError(f"saddle_placement must be 'targeted' or 'paper', got {self.saddle_placement!r}")
        for name in ("n_passes", "n_candidates", "max_ot_iterations", "disk_rank_draws"):
            if int(getattr(self, name)) < 1:
                raise InputError(f"{name} must be >= 1, got {getattr(self, name)!r}")
        if not (isinstance(self.disk_rank_tolerance, (int, float)) and 0 <= float(self.disk_rank_tolerance) < np.inf):
            raise InputError(f"disk_rank_tolerance must be a number >= 0, got {self.disk_rank_tolerance!r}")
        if not (isinstance(self.elevation_tolerance, (int, float)) and 0 < float(self.elevation_tolerance) < np.inf):
            raise InputError(f"elevation_tolerance must be a number > 0, got {self.elevation_tolerance!r}")
        r = self.saddle_slope_ratio
        if r is not None and not (isinstance(r, (int, float)) and 1 <= float(r) < np.inf):
            raise InputError(f"saddle_slope_ratio must be a number >= 1 or None, got {r!r}")
        f = self.ridge_slope_factor
        if not (isinstance(f, (int, float)) and 0 < float(f) < np.inf):
            raise InputError(f"ridge_slope_factor must be a number > 0, got {f!r}")
        for name in ("void_weight", "disk_weight", "disk_count_weight", "saddle_level_weight"):
            v = getattr(self, name)
            try:
                ok = bool(np.isfinite(float(v)) and float(v) >= 0)
            except (TypeError, ValueError):
                ok = False
            if not ok:
                raise InputError(f"{name} must be a number >= 0, got {v!r}")
        v = self.valley_network
        if isinstance(v, bool) or not (isinstance(v, (int, float, np.floating)) and 0 <= float(v) <= 1):
            raise InputError(f"valley_network must be a number in [0, 1], got {v!r}")
        if self.auto_elevation_m is not None and not float(self.auto_elevation_m) > 0:
            raise InputError(f"auto_elevation_m must be > 0 metres or None, got {self.auto_elevation_m!r}")
        g = self.gradient_tail
        if g is not None and not (isinstance(g, (int, float)) and 1 <= float(g) < np.inf):
            raise InputError(f"gradient_tail must be a number >= 1 or None, got {g!r}")
        if not (isinstance(self.fine_elevation_m, (int, float)) and 0 < float(self.fine_elevation_m) < np.inf):
            raise InputError(f"fine_elevation_m must be a number of metres > 0, got {self.fine_elevation_m!r}")

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


@dataclass
class _PeakSet:
    """Peak elevations and types, highest first, with the fixed ones and the fragment's forced ridges."""

    z: np.ndarray
    ptype: np.ndarray
    fixed: np.ndarray
    fxy: np.ndarray
    rho: np.ndarray
    forced: tuple[np.ndarray, np.ndarray] | None
    frag_edges: tuple[np.ndarray, np.ndarray, np.ndarray] | None


def synthesize_divide_tree(
    terrain_type: TerrainType | Sequence[TerrainType],
    *,
    size_m: float | tuple[float, float] | None = None,
    n_peaks: int | None = None,
    crs: Any = None,
    center: tuple[float, float] | None = None,
    domain: Domain | None = None,
    control_elevation: Any = None,
    control_density: Any = None,
    type_map: Any = None,
    fixed_peaks: Any = None,
    fragment: DivideTree | None = None,
    fragment_offset: tuple[float, float] = (0.0, 0.0),
    params: SynthesisParams | None = None,
    rng: SeedLike = None,
) -> DivideTree:
    """Synthesize a Divide Tree whose orometry follows ``terrain_type``.

    Parameters
    ----------
    terrain_type : one type, or a list of types mixed by ``type_map``.
    size_m : domain size in metres (scalar for a square, or (width, height));
        default 90 km.
    n_peaks : total number of peaks; default: each type's density x its area (cells
        where the density control is > 0), fixed and fragment peaks included.
    crs, center : output CRS (projected, metres) and domain centre (lon, lat);
        only ``center`` -> a local azimuthal equidistant projection centred there;
        neither -> a local frame with the south-west corner at (0, 0).
    domain : a ready :class:`~orokit.synthesis.controls.Domain` (from
        :func:`~orokit.synthesis.controls.make_domain`) instead of ``size_m``, ``crs``
        and ``center``; giving both is an error.
    control_elevation, control_density, type_map : C_H (m), C_P (>= 0, 0 = no
        peaks: sea, lakes) and C_T (type index) as raster paths, DataArrays (any CRS,
        resampled) or arrays (stretched over the domain, row 0 north).
    fixed_peaks : table (x, y, elevation) of user peaks kept as given.
    fragment : a real Divide Tree fragment (same metres frame, shifted by
        ``fragment_offset``) kept as is; the rest is completed around it.
    params : :class:`SynthesisParams` (passes, candidates, OT rounds, saddle placement,
        control grid, automatic C_H, elevation-band targets).
    rng : seed or Generator; the same seed gives the same tree.

    Returns
    -------
    DivideTree
        Peaks with columns x, y, elevation, type, fixed; ``attrs`` with the stage
        timings (``timings_s``), OT iterations and errors, seed and domain.

    Raises
    ------
    InputError
        No room for peaks, more fixed peaks than the domain holds, fixed peaks
        outside the domain, control rasters not overlapping the domain, ``domain``
        together with ``size_m``/``crs``/``center``.

    Notes
    -----
    1. Elevations are sampled (stratified) from each type's histogram; peaks are
       placed highest first by dart throwing in passes of 1, 2, 4, ... parts. Each
       peak picks one of ``n_candidates`` positions drawn from C_P with probability
       proportional to ``N(C_H - h; range(C_H)/20)`` times the remaining demand of
       its isolation distance and direction bins (the paper's acceptance with the
       isolation probabilities replaced by a deficit feedback, so the final
       isolation histograms converge to the targets).
    2. Ridges: Delaunay + MST with weight ``|Pi - Pj| / min(h)^rho``, times a factor favouring
       steep edges tuned to the type's ridge contrast (``follow_ridge_contrast``).
    3. Saddles start at ``min(h_a, h_b)``; OT rounds (dominance, then prominence)
       lower them; finally every peak keeps prominence >= eps.
    4. Saddle positions realise sampled key-saddle distances / directions (OT).

    Examples
    --------
    >>> import numpy as np, pandas as pd
    >>> from orokit.synthesis.terrain_type import TerrainType
    >>> rng = np.random.default_rng(0)
    >>> n = 200
    >>> z = rng.uniform(500, 2000, n); prom = rng.exponential(100, n) + 30
    >>> peaks = pd.DataFrame({"x": rng.uniform(0, 3e4, n), "y": rng.uniform(0, 3e4, n), "elevation": z,
    ...     "prominence": np.minimum(prom, z), "saddle_x": rng.uniform(0, 3e4, n), "saddle_y": rng.uniform(0, 3e4, n)})
    >>> t = TerrainType.from_peaks(peaks, area_km2=900.0)
    >>> tree = synthesize_divide_tree(t, size_m=20_000, rng=1)
    >>> tree.validate(); tree.n_peaks == round(t.peak_density_per_km2 * 400)
    True
    """
    p = SynthesisParams() if params is None else params
    if not isinstance(p, SynthesisParams):
        raise InputError(f"params must be a SynthesisParams, got {type(p).__name__}")
    rng = np.random.default_rng(rng)
    t0 = time.perf_counter()
    timings: dict[str, float] = {}
    types = [terrain_type] if isinstance(terrain_type, TerrainType) else list(terrain_type)
    if not types or not all(isinstance(t, TerrainType) for t in types):
        raise InputError("terrain_type must be a TerrainType or a non-empty list of them")
    domain = _resolve_domain(domain, size_m=size_m, crs=crs, center=center, grid_cells=p.grid_cells)
    controls = build_controls(domain, control_density=control_density, control_elevation=control_elevation,
                              type_map=type_map, n_types=len(types))
    eps = max(t.min_prominence_m for t in types)
    fixed_xyz, fixed_type = _fixed_peaks(fixed_peaks, fragment, fragment_offset, domain, controls)
    free_t = _free_peak_counts(types, controls, domain, n_peaks, fixed_xyz, fixed_type)
    # the default smooth C_H only once the counts are known to be sane (its smoothing is the
    # costly step on a tiny domain); nothing above draws from rng
    profile = (types[0].disks or {}).get("border_density") if p.border_density and len(types) == 1 else None
    if profile is not None and control_density is None:
        from orokit.synthesis.controls import border_density_map
        from orokit.synthesis.disks import shrink_border_density

        prov = types[0].provenance or {}
        n_real = int(prov.get("n_peaks") or round(types[0].peak_density_per_km2 * float(prov.get("area_km2") or 0.0)))
        profile = shrink_border_density(profile, n_real)
        controls = replace(controls, density=border_density_map(domain, profile))
    else:
        profile = None
    auto_m = p.auto_elevation_m if controls.elevation is None and len(types) == 1 else None
    nn_target = types[0].neighbour_gradient if p.follow_neighbour_gradient else None
    fit_fine = auto_m is not None and nn_target is not None
    fields = None
    rank_fit: dict[str, Any] | None = None
    rank_disks: Any = None
    if auto_m is not None:
        from orokit.synthesis.controls import random_elevation_fields

        disks = types[0].disks or {}

        def draw_fields(seed: Any) -> Any:
            return random_elevation_fields(
                domain, types[0].histograms["elevation"], correlation_m=float(auto_m), rng=seed,
                border_rank=disks.get("border_rank") if p.border_trend else None, fine_m=float(p.fine_elevation_m),
                fine_weights=FINE_WEIGHTS if fit_fine else (0.0,),
                density=None if profile is None else controls.density, valley_weight=float(p.valley_network))

        rank_disks = disks if p.follow_disk_rank and disks.get("median_rank") is not None else None
        fields = draw_fields(rng.integers(2**63) if fit_fine else rng)
        if fields is not None and not fit_fine:
            controls = replace(controls, elevation=next(fields))
    if p.follow_disk_rank and rank_disks is None:
        why = ("there is no automatic C_H to redraw (a user C_H, several types or auto_elevation_m None)"
               if auto_m is None else f"terrain type {types[0].name!r} records no disks median_rank (a type made "
               "before session 18, or from data narrower than 20 km); remake it with `orokit type` to follow it")
        warnings.warn(f"follow_disk_rank does nothing here: {why}", OrokitWarning, stacklevel=2)
    peaks = _peak_elevations(types, free_t, fixed_xyz, fixed_type, fragment, eps, rng)
    timings["elevations"] = time.perf_counter() - t0

    t1 = time.perf_counter()
    from orokit.synthesis.darts import place_peaks

    dip_tails = _forced_tail_placement(types) if p.forced_tail_placement else None

    def throw(ctrl, gen):
        return place_peaks(
            peaks.z, peaks.ptype, peaks.fixed, peaks.fxy, ctrl, domain,
            [t.histograms["isolation_distance"] for t in types], [t.histograms["isolation_direction"] for t in types],
            peaks.rho, n_passes=p.n_passes, n_candidates=p.n_candidates, forced=peaks.forced,
            void_weight=float(p.void_weight), disks=[t.disks for t in types], disk_weight=float(p.disk_weight),
            disk_count_weight=float(p.disk_count_weight),
            elevation_tolerance=float(p.elevation_tolerance),
            gradients=[t.gradient for t in types] if p.follow_gradient else None,
            gradient_tail=None if p.gradient_tail is None else float(p.gradient_tail), forced_tails=dip_tails,
            rng=gen,
        )

    def place(fields: Any, ctrl: Any, gen: Any) -> tuple[Any, np.ndarray, np.ndarray, Any, Any]:
        if fit_fine:
            assert fields is not None and nn_target is not None
            ctrl, (x_, y_, info_), fit_ = _fit_fine_elevation(
                fields, ctrl, throw, peaks.z, float(nn_target), int(gen.integers(2**63)),
                needs_reach=bool(p.fine_needs_reach))
            return ctrl, x_, y_, info_, fit_
        if fields is not None:
            ctrl = replace(ctrl, elevation=next(fields))
        x_, y_, info_ = throw(ctrl, gen)
        return ctrl, x_, y_, info_, None

    first_controls = controls
    placed = place(fields if fit_fine else None, controls, rng)
    if rank_disks is not None:
        # draw 0 is the placement made without the option (the same bytes when it passes); the redraws come
        # from a copy of the generator, so the ridges and saddles below draw as without the option
        rank_seed = int(copy.deepcopy(rng).integers(2**63))
        placed, rank_fit = _fit_disk_rank(
            placed, lambda sub: place(draw_fields(sub.integers(2**63)), first_controls, sub), rank_seed, rank_disks,
            peaks.z, domain, int(p.disk_rank_draws), float(p.disk_rank_tolerance))
    controls, px, py, dart_info, fine_fit = placed
    timings["dart_throwing"] = time.perf_counter() - t1

    t1 = time.perf_counter()
    contrast_target = _contrast_target(types, peaks.ptype) if p.follow_ridge_contrast else None
    tail_target = _forced_tail_target(types) if p.follow_forced_tail else None
    a, b, sx, sy, sz, movable, contrast, tail_fit = _ridges(px, py, peaks, fragment, fragment_offset, rng,
                                                            contrast_target, tail_target)
    timings["ridges"] = time.perf_counter() - t1

    t1 = time.perf_counter()
    slope_cap = _ridge_slope_target(types) if p.follow_ridge_slope else None
    if slope_cap is not None:
        slope_cap *= float(p.ridge_slope_factor)
    level_target = _saddle_level_target(types) if p.follow_saddle_level else None
    weights = [float(p.saddle_level_weight)]
    if level_target is not None:
        weights += [w for w in SADDLE_LEVEL_WEIGHTS if w > weights[0]]
    level_fit: dict[str, Any] | None = None
    plain = p.follow_plain_dominance and _plain_targets_recorded(types)
    state = rng.bit_generator.state
    tried: list[tuple[float, float, Any, Any]] = []
    for w in weights:
        rng.bit_generator.state = state  # every weight tried from the same draws
        out = _saddle_elevations(types, peaks, px, py, a, b, sz, movable, eps, p, rng, slope_cap, w, plain)
        if level_target is None:
            break
        from orokit.synthesis.saddles import saddle_level

        got = saddle_level(peaks.z, px, py, a, b, out[0])
        tried.append((abs(got - float(level_target)), got, out, rng.bit_generator.state))
        if got <= level_target:
            break
    if tried and level_target is not None:  # the closer of the last two weights tried
        _, got, out, after = min(tried[-2:], key=lambda t: t[0])
        rng.bit_generator.state = after
        level_fit = {"target": round(float(level_target), 4), "reached": round(got, 4),
                     "weight": weights[[t[2] is out for t in tried].index(True)]}
    sz, ot_info, below, band_mode = out
    timings["saddle_elevations"] = time.perf_counter() - t1

    t1 = time.perf_counter()
    if p.saddle_placement == "targeted":
        from orokit.synthesis.saddles import place_key_saddles

        nx_, ny_ = place_key_saddles(
            px, py, peaks.z, a, b, sz, peaks.ptype,
            [t.histograms["saddle_distance"] for t in types], [t.histograms["saddle_direction"] for t in types],
            movable=movable, max_slope_ratio=p.saddle_slope_ratio, rng=rng,
        )
        sx = np.where(movable, nx_, sx)
        sy = np.where(movable, ny_, sy)
    timings["saddle_positions"] = time.perf_counter() - t1
    timings["total"] = time.perf_counter() - t0

    tree = DivideTree(
        pd.DataFrame({"x": px, "y": py, "elevation": peaks.z, "type": peaks.ptype, "fixed": peaks.fixed}),
        pd.DataFrame({"x": sx, "y": sy, "elevation": sz}),
        pd.DataFrame({"peak_a": a, "peak_b": b, "saddle": np.arange(a.size, dtype=np.int64)}),
        domain.crs,
        {
            "units": "m",
            "min_prominence_m": float(eps),
            "terrain_types": [t.name for t in types],
            "rho": [float(t.rho) for t in types],
            "domain": {"x0": domain.x0, "y0": domain.y0, "width": domain.width, "height": domain.height},
            "local_grid": domain.crs is None,
            "n_passes": len(dart_info["passes"]),
            "ot_iterations": int(ot_info["iterations"]),
            "ot_errors": ot_info["errors"],
            "peaks_below_eps": int(below),
            "saddle_placement": p.saddle_placement,
            "saddle_targets": "elevation bands" if band_mode else "marginal",
            "timings_s": {k: round(v, 4) for k, v in timings.items()},
            "isolation": "nearest higher peak of the tree",
            "ridge_contrast": contrast,
            "neighbour_gradient": fine_fit,
            "max_ridge_slope": slope_cap,
            "saddle_level": level_fit,
            "disk_rank": rank_fit,
            "forced_tail": tail_fit,
            "plain_dominance": bool(plain),
        },
    )
    if "forced_tail" in dart_info:  # only with forced_tail_placement: trees made without it keep their bytes
        tree.attrs["forced_tail_placement"] = {k: [[round(float(v), 2) for v in row] for row in dart_info["forced_tail"][k]]
                                               for k in ("target", "placed")}
    logger.info("synthesized %d peaks, %d ridges in %.2f s (OT rounds %d)", tree.n_peaks, a.size,
                timings["total"], ot_info["iterations"])
    return tree


#: quantile levels of the disks' ``median_rank`` that ``follow_disk_rank`` keeps no lower than the type's
#: (the lowest disk, and the low tail the classifier's 40-odd disks sample)
DISK_RANK_LEVELS: tuple[float, ...] = (0.0, 0.05, 0.1)
#: quantile levels of the disks' ``median_rank`` and ``peak_relief_m`` that ``follow_disk_rank`` keeps no higher
#: than the type's (the high tail: a redraw must not buy its low disks with a valley in every disk)
DISK_RANK_HIGH_LEVELS: tuple[float, ...] = (0.9, 0.95, 1.0)


def disk_rank_margins(x: np.ndarray, y: np.ndarray, z: np.ndarray, extent: tuple[float, float, float, float],
                      disks: Any) -> dict[str, Any]:
    """How far a placement's 10 km disks lie inside the span of the type's (``disks``, a type's record).

    Margins (> 0 inside, < 0 outside): the disks' ``median_rank`` quantiles at :data:`DISK_RANK_LEVELS` minus the
    type's (``low``), the type's minus the placement's at :data:`DISK_RANK_HIGH_LEVELS` (``high``), and, when the
    type records ``peak_relief_m``, ``1 - placement / type`` of its quantiles at the high levels (``relief``).
    ``margin`` is the least of them (0 when all are inside). Disks on a grid of step radius / 4, every peak counted.
    """
    from orokit.synthesis.disks import disk_statistics

    levels = np.asarray(disks["levels"], float)
    radius = float(disks["radius_m"])
    st = disk_statistics(x, y, z, np.full(z.size, np.inf), extent, radius_m=radius, step_m=radius / 4.0)
    lo, hi = np.asarray(DISK_RANK_LEVELS), np.asarray(DISK_RANK_HIGH_LEVELS)
    target = np.asarray(disks["median_rank"], float)
    med = st["median_rank"][np.isfinite(st["median_rank"])]
    out: dict[str, Any] = {}
    if med.size:
        got_lo, got_hi = np.quantile(med, lo), np.quantile(med, hi)
        out["low"] = got_lo - np.interp(lo, levels, target)
        out["high"] = np.interp(hi, levels, target) - got_hi
    else:
        out["low"], out["high"] = np.full(lo.size, -1.0), np.full(hi.size, -1.0)
    if disks.get("peak_relief_m") is not None:
        rel = st["peak_relief_m"][np.isfinite(st["peak_relief_m"])]
        want = np.interp(hi, levels, np.asarray(disks["peak_relief_m"], float))
        got = np.quantile(rel, hi) if rel.size else np.zeros(hi.size)
        out["relief"] = np.where(want > 0, 1.0 - got / np.where(want > 0, want, 1.0), 0.0)
    out["margin"] = float(min(0.0, *(float(np.min(v)) for v in out.values())))
    return out


def _fit_disk_rank(first: Any, place: Any, seed: int, disks: Any, z: np.ndarray, domain: Any,
                   draws: int, tolerance: float) -> tuple[Any, dict[str, Any]]:
    """The placement (controls, x, y, ...: what ``place(rng)`` returns) among ``first`` (draw 0) and up to
    ``draws - 1`` C_H redraws whose disks lie inside the type's span (:func:`disk_rank_margins`, margin
    >= -``tolerance``), the first such, else the one with the largest margin (the earlier on ties), and a record
    of the fit. Redraw k uses ``place(default_rng([seed, k]))``."""
    ext = (domain.x0, domain.y0, domain.x0 + domain.width, domain.y0 + domain.height)
    best: tuple[float, int, Any, Any] | None = None
    k = 0
    for k in range(max(int(draws), 1)):
        out = first if k == 0 else place(np.random.default_rng([int(seed), k]))
        m = disk_rank_margins(out[1], out[2], z, ext, disks)
        if best is None or m["margin"] > best[0]:
            best = (m["margin"], k, out, m)
        if m["margin"] >= -float(tolerance):
            break
    assert best is not None
    rec: dict[str, Any] = {"low_levels": [float(v) for v in DISK_RANK_LEVELS],
                           "high_levels": [float(v) for v in DISK_RANK_HIGH_LEVELS],
                           "margin": round(best[0], 4), "draw": best[1], "draws": k + 1}
    rec.update({name: [round(float(v), 4) for v in best[3][name]] for name in ("low", "high", "relief")
                if name in best[3]})
    return best[2], rec


#: additions to the ridges' exponent rho tried, in order, by ``follow_forced_tail``
FORCED_TAIL_RHO_STEPS: tuple[float, ...] = (0.0, 0.5, 1.0, 2.0, 3.0, 4.0)


def _forced_tail_target(types: list[TerrainType]) -> tuple[float, float] | None:
    """The one type's ``forced_tail`` and its 90th-percentile prominence (m) that ``follow_forced_tail`` follows;
    None, with a warning saying why, when it cannot."""
    why = None
    share = types[0].forced_tail if len(types) == 1 else None
    if len(types) != 1:
        why = f"the synthesis mixes {len(types)} types"
    elif share is None:
        why = f"terrain type {types[0].name!r} has no forced_tail record (re-create it with `orokit type`)"
    if why is not None or share is None:
        warnings.warn(f"follow_forced_tail does nothing here: {why}", OrokitWarning, stacklevel=3)
        return None
    return float(share), _prominence_q90(types[0])


def _prominence_q90(ttype: TerrainType) -> float:
    """The 90th percentile of a type's prominence histogram (m), where ``forced_tail`` is counted."""
    h = ttype.histograms["prominence"]
    p = h.probabilities()
    cdf = np.concatenate([[0.0], np.cumsum(p)])
    e = np.asarray(h.edges, float)
    return float(np.interp(0.9, cdf / cdf[-1], e))


def _forced_tail_placement(types: list[TerrainType]) -> list[tuple[float, float] | None] | None:
    """Per type, its ``forced_tail`` and 90th-percentile prominence for ``forced_tail_placement`` (None for a type
    without the record); None, with a warning, when no type has the record."""
    tails = [None if t.forced_tail is None else (float(t.forced_tail), _prominence_q90(t)) for t in types]
    if all(v is None for v in tails):
        warnings.warn("forced_tail_placement does nothing here: no terrain type has a forced_tail record "
                      "(re-create it with `orokit type`)", OrokitWarning, stacklevel=3)
        return None
    return tails


#: weights of the saddle OT's level term tried, in order, by ``follow_saddle_level``
SADDLE_LEVEL_WEIGHTS: tuple[float, ...] = (0.0, 0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0)

#: weights of the ~1 km component of the automatic C_H tried, in order, by ``follow_neighbour_gradient``
FINE_WEIGHTS: tuple[float, ...] = (0.0, 0.25, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0)


def _fit_fine_elevation(fields: Any, controls: Any, throw: Any, z: np.ndarray, target: float, seed: int,
                        needs_reach: bool = False):
    """The first C_H of ``fields`` (fine weights :data:`FINE_WEIGHTS`) whose peaks' median neighbour
    gradient reaches ``target``, or the closer of it and the one before (log ratio); with
    ``needs_reach``, the first (no fine component) when no weight reaches it.

    Each weight places the peaks with the same random draws (``seed``), so the gradient grows
    with the weight and the trials differ only by it. Returns the controls, the placement
    ``(px, py, info)`` kept and a record of the fit.
    """
    from orokit.synthesis.orometry import neighbour_gradients

    tried: list[tuple[float, float, Any, Any]] = []
    for w, field in zip(FINE_WEIGHTS, fields):
        ctrl = replace(controls, elevation=field)
        placed = throw(ctrl, np.random.default_rng(seed))
        g = neighbour_gradients(placed[0], placed[1], z)
        got = float(np.median(g)) if g.size else float("nan")
        tried.append((w, got, ctrl, placed))
        if not np.isfinite(got) or got >= target:
            break
    def miss(t):
        return abs(np.log(max(t[1], 1e-12) / max(target, 1e-12))) if np.isfinite(t[1]) else np.inf
    reached = np.isfinite(tried[-1][1]) and tried[-1][1] >= target
    best = tried[0] if needs_reach and not reached else min(tried[-2:], key=miss)
    record = {"target": round(target, 5), "reached": round(best[1], 5), "fine_weight": best[0],
              "trials": len(tried)}
    logger.debug("neighbour gradient fit: %s", record)
    return best[2], best[3], record


def _saddle_level_target(types: list[TerrainType]) -> float | None:
    """The one type's ``saddle_level`` that ``follow_saddle_level`` follows; None, with a warning saying why,
    for a mixture of types or a type that records none (the option then does nothing)."""
    if len(types) > 1:
        warnings.warn(f"follow_saddle_level does nothing here: the synthesis mixes {len(types)} types and follows "
                      "one type's saddle level only; synthesize each type alone to follow its level",
                      OrokitWarning, stacklevel=3)
        return None
    if types[0].saddle_level is None:
        warnings.warn(f"follow_saddle_level does nothing here: terrain type {types[0].name!r} records no "
                      "saddle_level (a type made before session 17); remake it with `orokit type` to follow it",
                      OrokitWarning, stacklevel=3)
        return None
    return float(types[0].saddle_level)


def _plain_targets_recorded(types: list[TerrainType]) -> bool:
    """Whether every type records ``plain_dominance`` (else a warning: ``follow_plain_dominance`` does nothing)."""
    missing = [t.name for t in types if t.plain_dominance is None]
    if missing:
        warnings.warn(f"follow_plain_dominance does nothing here: terrain type {missing[0]!r} records no "
                      "plain_dominance (a type made before session 19); remake it with `orokit type` to follow it",
                      OrokitWarning, stacklevel=3)
    return not missing


def _ridge_slope_target(types: list[TerrainType]) -> float | None:
    """The types' largest recorded ``max_ridge_slope`` (None if any type lacks it)."""
    values = [t.max_ridge_slope for t in types]
    return None if any(v is None for v in values) else float(max(v for v in values if v is not None))


def _resolve_domain(domain: Domain | None, *, size_m: Any, crs: Any, center: Any, grid_cells: int) -> Domain:
    """The output domain: ``domain`` as given, or built from size, CRS and centre (never both)."""
    if domain is None:
        return make_domain(90_000.0 if size_m is None else size_m, crs=crs, center=center, grid_cells=grid_cells)
    given = [name for name, v in (("size_m", size_m), ("crs", crs), ("center", center)) if v is not None]
    if given:
        raise InputError(f"pass either domain= or {', '.join(given)}, not both: the domain already fixes its size, "
                         "CRS and position")
    if not isinstance(domain, Domain):
        raise InputError(f"domain must be an orokit.synthesis.controls.Domain (see make_domain), got "
                         f"{type(domain).__name__}")
    return domain


def _fixed_peaks(fixed_peaks: Any, fragment: DivideTree | None, offset: tuple[float, float], domain: Domain,
                 controls: Any) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) x, y, elevation of the fragment's then the user's fixed peaks, and their type index."""
    user = _fixed_frame(fixed_peaks)
    _check_fixed(user, getattr(fixed_peaks, "attrs", {}).get("source", "the fixed peaks"))
    n_user = len(user)
    if fragment is not None:
        fragment.validate()
        fp = fragment.peaks[["x", "y", "elevation"]].astype(float).copy()
        fp["x"] += offset[0]
        fp["y"] += offset[1]
        user = pd.concat([fp, user], ignore_index=True)
        if n_user:
            _check_fixed(user, "the fragment peaks (first) and fixed peaks")
    fixed_xyz = user.to_numpy(float).reshape(-1, 3)
    if fixed_xyz.size and not domain.contains(fixed_xyz[:, 0], fixed_xyz[:, 1]).all():
        k = int((~domain.contains(fixed_xyz[:, 0], fixed_xyz[:, 1])).sum())
        raise InputError(f"{k} fixed/fragment peaks lie outside the domain "
                         f"x {domain.x0:.0f}..{domain.x0 + domain.width:.0f}, y {domain.y0:.0f}..{domain.y0 + domain.height:.0f}")
    if fixed_xyz.size and not (fixed_xyz[:, 2] > 0).all():
        raise InputError("fixed peaks need elevations > 0 m")
    fr, fc = domain.cell_index(fixed_xyz[:, 0], fixed_xyz[:, 1])
    return fixed_xyz, controls.type_index[fr, fc]


def _free_peak_counts(types: list[TerrainType], controls: Any, domain: Domain, n_peaks: int | None,
                      fixed_xyz: np.ndarray, fixed_type: np.ndarray) -> np.ndarray:
    """Peaks to place per type, fixed peaks deducted (checks the limits before allocating)."""
    cell_km2 = domain.cell[0] * domain.cell[1] / 1e6
    area_t = np.array([((controls.type_index == t) & (controls.density > 0)).sum() * cell_km2 for t in range(len(types))])
    dens_t = np.array([t.peak_density_per_km2 for t in types])
    expected = dens_t * area_t
    total = float(np.sum(expected)) if n_peaks is None else float(n_peaks)
    if not np.isfinite(total) or total > MAX_PEAKS:
        dens = ", ".join(f"{t.name}: {t.peak_density_per_km2:.4g}" for t in types)
        raise OrokitError(
            f"the domain would hold {total:.4g} peaks "
            f"({domain.area_km2:.4g} km2 at peak densities {dens} per km2), more than the limit of {MAX_PEAKS}; "
            "a density this high usually comes from a terrain type built in degrees instead of metres "
            "(re-create it with `orokit type` from a current analysis), else pass a smaller size_m or n_peaks"
        )
    if n_peaks is None:
        n_t = np.rint(expected).astype(np.int64)
    else:
        if int(n_peaks) < 1:
            raise InputError(f"n_peaks must be >= 1, got {n_peaks}")
        share = expected / expected.sum() if expected.sum() > 0 else np.full(len(types), 1 / len(types))
        n_t = np.floor(share * int(n_peaks)).astype(np.int64)
        n_t[np.argmax(share)] += int(n_peaks) - n_t.sum()
    fixed_per_t = np.bincount(fixed_type, minlength=len(types))
    if len(fixed_xyz) > n_t.sum():
        raise InputError(
            f"{len(fixed_xyz)} fixed peaks but the domain holds only {int(n_t.sum())} peaks "
            f"({domain.area_km2:.0f} km2 at the type density); enlarge the domain or pass a larger n_peaks"
        )
    free_t = np.maximum(n_t - fixed_per_t, 0)
    if free_t.sum() + len(fixed_xyz) < 2:
        raise InputError(
            f"the domain holds {int(n_t.sum())} peaks at the type density ({domain.area_km2:.4g} km2): "
            "too few for a Divide Tree; enlarge size_m (CLI: --size) or pass n_peaks >= 2 (--n-peaks)"
        )
    return free_t


def _peak_elevations(types: list[TerrainType], free_t: np.ndarray, fixed_xyz: np.ndarray, fixed_type: np.ndarray,
                     fragment: DivideTree | None, eps: float, rng: np.random.Generator) -> _PeakSet:
    """Stratified elevation samples per type plus the fixed peaks, sorted highest first."""
    z_parts, t_parts = [], []
    for t, typ in enumerate(types):
        zt = typ.histograms["elevation"].sample(int(free_t[t]), rng)
        z_parts.append(np.maximum(zt, eps + 1.0))
        t_parts.append(np.full(zt.size, t))
    z_free = np.concatenate(z_parts)
    t_free = np.concatenate(t_parts).astype(np.int64)
    z_all = np.concatenate([fixed_xyz[:, 2], z_free])
    ptype = np.concatenate([fixed_type, t_free]).astype(np.int64)
    fixed = np.zeros(z_all.size, bool)
    fixed[: len(fixed_xyz)] = True
    fxy = np.zeros((z_all.size, 2))
    fxy[: len(fixed_xyz)] = fixed_xyz[:, :2]
    src_id = np.arange(z_all.size)  # index before sorting
    order = np.lexsort((src_id, -z_all))
    z, ptype, fixed, fxy = z_all[order], ptype[order], fixed[order], fxy[order]
    new_of_src = np.empty_like(order)
    new_of_src[order] = np.arange(order.size)
    forced = frag_edges = None
    if fragment is not None and len(fragment.edges):
        fa = new_of_src[fragment.edges["peak_a"].to_numpy(np.int64)]
        fb = new_of_src[fragment.edges["peak_b"].to_numpy(np.int64)]
        forced = (fa, fb)
        frag_edges = (fa, fb, fragment.edges["saddle"].to_numpy(np.int64))
    rho = np.array([types[t].rho for t in ptype], float)
    return _PeakSet(z, ptype, fixed, fxy, rho, forced, frag_edges)


def _contrast_target(types: list[TerrainType], ptype: np.ndarray) -> float | None:
    """The types' ridge contrast, weighted by their peak counts (None if any type lacks it)."""
    values = [t.ridge_contrast for t in types]
    if any(v is None for v in values):
        return None
    n = np.bincount(ptype, minlength=len(types)).astype(float)
    return float(np.average([float(v) for v in values if v is not None], weights=n)) if n.sum() else None


def _ridges(px: np.ndarray, py: np.ndarray, peaks: _PeakSet, fragment: DivideTree | None,
            offset: tuple[float, float], rng: np.random.Generator, contrast_target: float | None = None,
            tail_target: tuple[float, float] | None = None):
    """Delaunay-MST ridges (fitted to the ridge contrast and the forced tail if given), initial saddles at
    min(h_a, h_b), the fragment's saddles frozen."""
    from orokit.synthesis.ridges import delaunay_mst, fit_ridge_contrast, place_saddles_on_ridges
    from orokit.synthesis.saddles import forced_tail

    z = peaks.z
    contrast: dict[str, float] | None = None
    tail_fit: dict[str, float] | None = None
    steps = FORCED_TAIL_RHO_STEPS if tail_target is not None and z.size >= 4 else (0.0,)
    tried = []
    for step in steps:
        rho = peaks.rho + step
        if contrast_target is not None and z.size >= 4:
            a, b, strength, reached = fit_ridge_contrast(px, py, z, contrast_target, rho=rho, forced=peaks.forced)
            contrast = {"target": round(contrast_target, 4), "reached": round(reached, 4),
                        "strength": round(strength, 4)}
        else:
            a, b = delaunay_mst(px, py, z, rho=rho, forced=peaks.forced)
        if tail_target is None:
            break
        share = forced_tail(z, a, b, tail_target[1])
        tried.append((abs(share - tail_target[0]), share, step, a, b, contrast))
        if share <= tail_target[0]:
            break
    if tried and tail_target is not None:  # the closer of the last two steps tried
        _, share, step, a, b, contrast = min(tried[-2:], key=lambda t: t[0])
        tail_fit = {"target": round(tail_target[0], 4), "reached": round(share, 4), "rho_added": step}
    sx, sy, _ = place_saddles_on_ridges(px, py, a, b, rng=rng)
    sz = np.minimum(z[a], z[b])
    movable = np.ones(a.size, bool)
    if peaks.frag_edges is not None and fragment is not None:
        key = {(min(i, j), max(i, j)): s for i, j, s in zip(*peaks.frag_edges)}
        fs = fragment.saddles
        for e_i, (i, j) in enumerate(zip(a.tolist(), b.tolist())):
            s = key.get((min(i, j), max(i, j)))
            if s is not None:
                movable[e_i] = False
                sx[e_i] = float(fs["x"].iloc[s]) + offset[0]
                sy[e_i] = float(fs["y"].iloc[s]) + offset[1]
                sz[e_i] = float(fs["elevation"].iloc[s])
    return a, b, sx, sy, sz, movable, contrast, tail_fit


def _saddle_elevations(types: list[TerrainType], peaks: _PeakSet, px: np.ndarray, py: np.ndarray, a: np.ndarray,
                       b: np.ndarray, sz0: np.ndarray, movable: np.ndarray, eps: float, p: SynthesisParams,
                       rng: np.random.Generator, max_ridge_slope: float | None = None, level_weight: float = 0.0,
                       plain: bool = False):
    """OT saddle elevations; with use_bands="auto", the target set that matches the type's marginals better
    (with ``plain``, the types' ``plain_dominance`` is a third feature of the OT)."""
    from orokit.synthesis.saddles import assign_saddle_elevations, enforce_min_prominence, max_bin_errors

    z, ptype = peaks.z, peaks.ptype
    marginal = _saddle_targets(types, ptype, z, False)
    has_bands = any(t.bands is not None for t in types)
    modes = {"auto": [False, True] if has_bands else [False], True: [True], False: [False]}[p.use_bands]
    best: tuple[float, np.ndarray, dict, int, bool] | None = None
    for mode in modes:
        cand, info = assign_saddle_elevations(z, px, py, a, b, sz0, _saddle_targets(types, ptype, z, mode, plain),
                                              movable=movable, max_iterations=p.max_ot_iterations,
                                              max_ridge_slope=max_ridge_slope,
                                              level_weight=level_weight, rng=rng)
        cand, below_c = enforce_min_prominence(z, a, b, cand, eps)
        score = max(max_bin_errors(z, a, b, cand, marginal))
        if plain:  # judged as the OT's rounds are: the plain dominance too, over PLAIN_GATE
            from orokit.synthesis.saddles import PLAIN_GATE, plain_dominance

            pe = max_bin_errors(z, a, b, cand, _saddle_targets(types, ptype, z, False, True),
                                plain_dominance(z, px, py, a, b, cand))[2]
            score = max(score, pe / PLAIN_GATE)
        logger.debug("saddle targets %s: worst max-bin error %.4f", "per band" if mode else "marginal", score)
        if best is None or score < best[0]:
            best = (score, cand, info, below_c, mode)
    assert best is not None  # modes is never empty
    _, sz, ot_info, below, band_mode = best
    return sz, ot_info, below, band_mode


def _saddle_targets(types, ptype: np.ndarray, z: np.ndarray, use_bands: bool, plain: bool = False):
    """Target histograms per (type, elevation band) group (with ``plain``, each type's ``plain_dominance``)."""
    from orokit.synthesis.saddles import SaddleTargets
    from orokit.synthesis.terrain_type import band_histograms

    group = np.zeros(z.size, np.int64)
    dom: list[Any] = []
    prom: list[Any] = []
    owner: list[int] = []
    for t, typ in enumerate(types):
        if use_bands:
            edges, ph, dh = band_histograms(typ)
        else:
            edges, ph, dh = (np.array([-np.inf, np.inf]), [typ.histograms["prominence"]],
                             [typ.histograms["dominance"]])
        mine = ptype == t
        band = np.clip(np.searchsorted(edges[1:-1], z[mine], side="right"), 0, len(ph) - 1)
        group[mine] = len(prom) + band
        prom.extend(ph)
        dom.extend(dh)
        owner.extend([t] * len(ph))
    return SaddleTargets(group, dom, prom, owner, [types[t].plain_dominance for t in owner] if plain else None)


def peaks_table(tree: DivideTree):
    """Peaks GeoDataFrame with the columns of ``orokit analyze`` (index ``peak_id``).

    Follows :data:`orokit.topology.tables.PEAK_SCHEMA`. Raster columns (row, col,
    saddle_row...) are -1 (none): a synthesized tree has no grid.
    Isolation is measured to the nearest higher peak of the tree; ``lon``/``lat`` are
    filled when the tree has a real CRS.
    """
    import geopandas as gpd

    from orokit.synthesis.orometry import tree_orometry

    o = tree_orometry(tree)
    x = tree.peaks["x"].to_numpy(float)
    y = tree.peaks["y"].to_numpy(float)
    n = x.size
    nan = np.full(n, np.nan)
    none = np.full(n, NONE_ID, np.int64)
    lon, lat = nan.copy(), nan.copy()
    if tree.crs is not None:
        from pyproj import Transformer

        lon, lat = Transformer.from_crs(tree.crs, "EPSG:4326", always_xy=True).transform(x, y)
    parent = o["island_parent"].to_numpy(np.int64)
    parents = tree.parents()
    frame = pd.DataFrame(
        {
            "row": none, "col": none, "x": x, "y": y, "lon": np.asarray(lon, float), "lat": np.asarray(lat, float),
            "elevation": tree.peaks["elevation"].to_numpy(float),
            "prominence": o["prominence"].to_numpy(float),
            "saddle_row": none, "saddle_col": none,
            "saddle_x": o["saddle_x"].to_numpy(float), "saddle_y": o["saddle_y"].to_numpy(float),
            "saddle_elevation": o["saddle_elevation"].to_numpy(float),
            "island_parent": parent, "island_parent_row": none, "island_parent_col": none,
            "line_parent": parents["line_parent"].to_numpy(np.int64), "line_parent_row": none, "line_parent_col": none,
            "prominence_parent": parents["prominence_parent"].to_numpy(np.int64),
            "prominence_parent_row": none, "prominence_parent_col": none,
            "dominance": o["dominance"].to_numpy(float),
            "isolation": o["isolation"].to_numpy(float),
            "isolation_row": none, "isolation_col": none,
            "isolation_x": o["isolation_x"].to_numpy(float), "isolation_y": o["isolation_y"].to_numpy(float),
            "prominence_exact": np.ones(n, bool),
            "isolation_exact": np.isfinite(o["isolation"].to_numpy(float)),
        },
        index=pd.RangeIndex(n, name="peak_id"),
    )
    for extra in ("type", "fixed"):
        if extra in tree.peaks.columns:
            frame[extra] = tree.peaks[extra].to_numpy()
    table = gpd.GeoDataFrame(frame, geometry=gpd.points_from_xy(x, y), crs=tree.crs)
    validate_peak_table(table)
    return table
