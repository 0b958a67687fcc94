"""Rusnell 2009 backend: terrain as blended least-cost fields from generator nodes.

B. Rusnell, D. Mould, M. Eramian, *Feature-rich distance-based terrain synthesis*,
The Visual Computer 25 (2009) 573-579 (doi:10.1007/s00371-009-0350-5). From a Divide
Tree: one feature per peak (the peak and its half-ridges to its saddles), generator cost
= highest peak - elevation (m); the feature profile is fitted on a real DEM (the
exemplar) with scikit-learn's ``IsotonicRegression``, or ``profile=none`` (w_s = 1).
Secondary ridges are least-cost paths from random nodes (§4, ``secondary``); halting the
searches at water is the paper's future work (§6, ``water``: the shared rivers stop
them); ``generators=FILE`` reads the paper's own input (generator nodes with costs and
feature ids) instead of the tree. Not implemented: the pareidolia (shadow image) mode.

Sea level from a tree (session 9): the paper's single plain ``highest peak - c_s`` held every cell
no feature reaches, and every cell with a slope below 2 deg lay on it (session 8, ranking trees seed 0,
``sea_level=exemplar``: appalachians 45.7 % of the cells, karakoram 26.6 %, norway 29.1 %, against a
flat share of 3.9 %, 3.2 % and 10.9 % in the real DEMs). The default ``sea_level=rivers`` makes it a
per-location sea level derived from the inputs: the plain rises from the shared rivers' beds at the
exemplar DEM's mean slope, falls from the generators at the same slope and stays below the lowest
saddle of the feature owning the cell (:func:`river_plain`, :func:`generator_cap`, :func:`saddle_cap`).
"""
from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import xarray as xr

from orokit.errors import InputError
from orokit.generators import _rusnell_kernels as _k
from orokit.generators.base import as_dataarray, check_crs, exemplar_slope, spread, tree_arrays
from orokit.raster.rasterize import Grid

logger = logging.getLogger(__name__)

__all__ = ["RusnellParams", "PRESETS", "fit_profile", "edge_weights", "features", "file_features", "river_cells",
           "secondary_paths", "learn", "render", "blend", "river_plain", "generator_cap", "saddle_cap"]

#: Table 1 of the paper: mu_w, r, s, b
PRESETS: dict[str, tuple[float, float, float, float]] = {
    "crater": (1.5, 1.0, 1.1, 4.0),
    "cinder-cone": (1.0, 0.5, 3.0, 3.0),
    "foothills": (0.75, 0.375, 2.5, 3.0),
}
#: per-feature searches stop below this share of the all-generator field's height (paper: 5 %)
HALT_FRACTION = 0.05
#: number of samples of the profile's slope table
TABLE_SIZE = 256


@dataclass(frozen=True)
class RusnellParams:
    """Parameters of the Rusnell 2009 backend.

    preset : a row of the paper's Table 1 (``crater``, ``cinder-cone``, ``foothills``) giving
        mu_w, r, s and b; a value given explicitly (not NaN) overrides the preset's.
    mu_w : mean edge weight, in metres of cost per metre of step (orokit: the paper's
        weights have no unit; costs here are metres below the highest peak, so mu_w is the
        slope of the plain, w_s = 1, fields).
    r : maximum edge weight deviation, ``0 <= r < mu_w`` (roughness).
    s : sea level scale: ``c_s = s x`` the largest generator cost.
    b : blending bias of eq. 2 (0: mean of the features' heights, large: their maximum).
    profile : ``fit`` (isotonic fit of the drop below the nearest peak against the
        distance to it on the exemplar DEM; scaled vertically to ``[0, c_s]`` as in §3.1) or
        ``none`` (w_s = 1: the ablation).
    secondary : number of secondary ridges (§4): least-cost paths of the all-generator field
        from random reached nodes down to a generator; their nodes join that generator's
        feature as generators. The paper gives no count; default 0.
    secondary_scale : the path nodes' cost, "a function of the existing node cost" (§4):
        ``c_g + secondary_scale x (C_a - c_g)`` with ``c_g`` the cost of the generator the
        path reaches (1 leaves the field unchanged, 0 lifts the ridge to the generator;
        orokit's default 0.5; the paper bounds it below, as c_g does here).
    water : halt every search at the river cells of the shared rivers (the paper's future
        work, §6): rivers are reached but not crossed.
    sea_level : where the plain no feature reaches lies. ``preset`` (the paper: ``c_s = s x``
        the largest generator cost; from a tree the plain then lies ``(s - 1) x`` the tree's
        relief below its lowest saddle: 1.5 reliefs with the foothills preset),
        ``exemplar`` (from a tree: at the exemplar DEM's 1st-percentile elevation,
        ``c_s = highest peak - that``, at least 1.05 x the largest generator cost; ``s`` is
        then unused), ``rivers`` (session 9, per location: ``exemplar``'s ``c_s``, and beneath
        the features a plain that rises from the shared rivers' beds at the exemplar DEM's mean
        slope (:func:`orokit.generators.base.exemplar_slope`) and falls from the generators at
        the same slope, :func:`river_plain`; the elevation is the larger of the two, generator
        cells unchanged) or ``auto`` (the default: ``rivers`` when a tree is rendered with an
        exemplar and rivers, ``exemplar`` with an exemplar only, else ``preset``).
    cap_quantile : with ``sea_level=rivers``, the plain falls from the generators at this quantile
        of the exemplar's slope angles (NaN, the default: its mean slope, as it rises from the rivers).
    saddle_cap : with ``sea_level=rivers``, keep the plain below the lowest saddle of the feature
        owning each cell (nearest generator cell), so it buries no peak (default true). Ranking
        trees, seed 0, landform targets met of 9 (appalachians / karakoram / norway / sahara) and
        sahara's tree peaks recovered: ``exemplar`` 1 / 3 / 3 / 5, 88 %; ``rivers`` without the
        saddle cap 7 / 4 / 5 / 6, 19 % (the plain rose above sahara's low hills); with it
        (default) see docs/generators.md. Ranking trees, seed 0 (appalachians, karakoram, norway,
        sahara): slope W1 29.5 / 33.1 / 25.1 / 16.4 deg with ``preset``, 11.0 / 9.2 / 4.9 / 2.5
        with ``exemplar``; landform targets met 0 / 3 / 3 / 2 of 9 against 1 / 3 / 3 / 5; the
        flat share grows (0.19 -> 0.45 on appalachians: features on a plain).
    generators : a CSV of the paper's own generator nodes (columns ``x, y, cost`` in the
        grid's coordinates and cost metres, optional ``feature``; CLI ``--param
        generators=FILE``) used instead of the tree; elevation = ``c_s -`` blended cost.
    """

    preset: str = field(default="foothills", metadata={"choices": tuple(PRESETS)})
    mu_w: float = math.nan
    r: float = math.nan
    s: float = math.nan
    b: float = math.nan
    profile: str = field(default="fit", metadata={"choices": ("fit", "none")})
    secondary: int = 0
    secondary_scale: float = 0.5
    water: bool = False
    sea_level: str = field(default="auto", metadata={"choices": ("auto", "preset", "exemplar", "rivers")})
    cap_quantile: float = math.nan
    saddle_cap: bool = True
    generators: str = field(default="", metadata={"file": "table"})

    def __post_init__(self) -> None:
        if self.preset not in PRESETS:
            raise InputError(f"preset={self.preset!r} is not one of {', '.join(PRESETS)}")
        for name, v in zip(("mu_w", "r", "s", "b"), PRESETS[self.preset]):
            if math.isnan(getattr(self, name)):
                object.__setattr__(self, name, float(v))
        if not (self.mu_w > 0 and math.isfinite(self.mu_w)):
            raise InputError(f"mu_w must be a positive number, got {self.mu_w!r}")
        if not (0.0 <= self.r < self.mu_w):
            raise InputError(f"r must satisfy 0 <= r < mu_w ({self.mu_w:g}), got {self.r!r}")
        if not (self.s > 1.0 and math.isfinite(self.s)):
            raise InputError(f"s (sea level scale) must be > 1 so c_s exceeds every generator cost, got {self.s!r}")
        if not (self.b >= 0 and math.isfinite(self.b)):
            raise InputError(f"b (blending bias) must be >= 0, got {self.b!r}")
        if self.profile not in ("fit", "none"):
            raise InputError(f"profile={self.profile!r} is not one of fit, none")
        if not (0.0 <= self.secondary_scale <= 1.0):
            raise InputError(f"secondary_scale must be in [0, 1], got {self.secondary_scale!r}")
        if self.sea_level not in ("auto", "preset", "exemplar", "rivers"):
            raise InputError(f"sea_level={self.sea_level!r} is not one of auto, preset, exemplar, rivers")
        if not (math.isnan(self.cap_quantile) or 0.0 <= self.cap_quantile <= 1.0):
            raise InputError(f"cap_quantile must be NaN (the exemplar's mean slope) or in [0, 1], got {self.cap_quantile!r}")
        if not (isinstance(self.secondary, int) and 0 <= self.secondary <= 100_000):
            raise InputError(f"secondary must be an integer in [0, 100000], got {self.secondary!r}")


def fit_profile(distance_m: np.ndarray, drop_m: np.ndarray, *, n_bins: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """Monotone feature profile ``drop(distance)`` from samples (isotonic regression).

    Samples are binned by distance (``n_bins`` up to the 99th percentile), each bin's
    median drop is fitted by :class:`sklearn.isotonic.IsotonicRegression` (increasing,
    weighted by the bin counts). Returns ``(distance_m, drop_m)`` starting at ``(0, 0)``,
    non-decreasing.

    Raises
    ------
    InputError : fewer than 10 finite samples.
    """
    from sklearn.isotonic import IsotonicRegression

    d = np.asarray(distance_m, float).ravel()
    h = np.asarray(drop_m, float).ravel()
    ok = np.isfinite(d) & np.isfinite(h)
    d, h = d[ok], h[ok]
    if d.size < 10:
        raise InputError(f"the exemplar gives {d.size} usable samples for the profile fit; it needs at least 10 "
                         "(a DEM with peaks and slopes)")
    hi = float(np.quantile(d, 0.99))
    if hi <= 0:
        raise InputError("the exemplar's cells are all at their nearest peak; no profile can be fitted")
    edges = np.linspace(0.0, hi, n_bins + 1)
    idx = np.clip(np.searchsorted(edges, d, side="right") - 1, 0, n_bins - 1)
    keep = d <= hi
    centres, medians, counts = [], [], []
    for k in range(n_bins):
        sel = h[keep & (idx == k)]
        if sel.size:
            centres.append(0.5 * (edges[k] + edges[k + 1]))
            medians.append(float(np.median(sel)))
            counts.append(sel.size)
    iso = IsotonicRegression(increasing=True, y_min=0.0).fit(centres, medians, sample_weight=counts)
    fit = iso.predict(centres)
    return np.concatenate([[0.0], centres]), np.concatenate([[0.0], fit])


def slope_table(dist_m: np.ndarray, drop_m: np.ndarray, cs: float, mu_w: float,
                size: int = TABLE_SIZE) -> np.ndarray:
    """w_s(c_m) sampled at ``size`` costs in ``[0, c_s]``: the profile scaled vertically to
    ``[0, c_s]``, its slope (cost per metre) at the distance where it reaches c_m, / mu_w.

    Raises
    ------
    InputError : the profile decreases somewhere (profiles must be monotone, §3.1) or is flat.
    """
    dist_m = np.asarray(dist_m, float)
    drop_m = np.asarray(drop_m, float)
    if dist_m.size < 2 or np.any(np.diff(dist_m) <= 0):
        raise InputError("the profile's distances must increase strictly")
    if np.any(np.diff(drop_m) < 0):
        raise InputError("the profile must be monotone (its drop may not decrease with distance); "
                         "non-monotone profiles give ill-defined path costs")
    if drop_m[-1] - drop_m[0] <= 0:
        raise InputError("the profile is flat; it cannot be scaled to the sea level cost")
    p = (drop_m - drop_m[0]) / (drop_m[-1] - drop_m[0]) * cs
    seg_slope = np.diff(p) / np.diff(dist_m)  # cost per metre on each piece
    floor = 1e-3 * cs / dist_m[-1]
    seg_slope = np.maximum(seg_slope, floor)
    c = np.linspace(0.0, cs, size)
    k = np.clip(np.searchsorted(p, c, side="right") - 1, 0, seg_slope.size - 1)
    return seg_slope[k] / mu_w


def exemplar_profile(exemplar: xr.DataArray, *, min_prominence_m: float = 30.0) -> tuple[np.ndarray, np.ndarray]:
    """Profile of a real DEM: drop below the nearest peak (prominence >= eps) against the distance to it."""
    import orokit
    from scipy.spatial import cKDTree

    res = orokit.analyze(exemplar, min_prominence_m=min_prominence_m, isolation=False)
    pk = res.peaks
    if len(pk) == 0:
        raise InputError(f"the exemplar DEM has no peak with prominence >= {min_prominence_m:g} m; "
                         "choose a DEM with relief for the profile fit, or --param profile=none")
    t = exemplar.rio.transform()
    dx, dy = abs(float(t.a)), abs(float(t.e))
    z = np.asarray(exemplar.values, float)
    ii, jj = np.mgrid[0:z.shape[0], 0:z.shape[1]]
    pts = np.column_stack([ii.ravel() * dy, jj.ravel() * dx])
    ppts = np.column_stack([pk["row"].to_numpy() * dy, pk["col"].to_numpy() * dx])
    dist, near = cKDTree(ppts).query(pts)
    drop = pk["elevation"].to_numpy()[near] - z.ravel()
    return fit_profile(dist, drop)


def edge_weights(ny: int, nx: int, mu_w: float, r: float, rng: np.random.Generator, *,
                 cell_m: float = 1.0) -> np.ndarray:
    """(ny, nx, 4) weights of the forward edges E, SE, S, SW: ``(mu_w + r U[-1, 1]) x`` step
    length (``cell_m`` or ``sqrt(2) cell_m``)."""
    w = rng.uniform(-1.0, 1.0, size=(ny, nx, 4))
    w *= r
    w += mu_w
    w *= cell_m
    w[:, :, 1] *= math.sqrt(2.0)
    w[:, :, 3] *= math.sqrt(2.0)
    return w


def features(tree, grid: Grid) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Generator cells of every peak's feature: the peak and its half-ridges (sampled every
    half cell, elevation linear from peak to saddle) as ``(rows, cols, elevations)``."""
    a = tree_arrays(tree)
    out = []
    half: list[list[tuple[np.ndarray, np.ndarray]]] = [[] for _ in range(a.peaks.shape[0])]
    for pa, pb, sd in a.edges:
        for p in (pa, pb):
            p0, p1 = a.peaks[p], a.saddles[sd]
            n = max(int(math.ceil(math.hypot(*(p1[:2] - p0[:2])) / (0.5 * grid.cell_size_m))), 1) + 1
            t = np.linspace(0.0, 1.0, n)
            xy = p0[None, :2] + t[:, None] * (p1[None, :2] - p0[None, :2])
            half[p].append((xy, p0[2] + t * (p1[2] - p0[2])))
    for p in range(a.peaks.shape[0]):
        xy = np.concatenate([a.peaks[p:p + 1, :2]] + [h[0] for h in half[p]])
        z = np.concatenate([a.peaks[p:p + 1, 2]] + [h[1] for h in half[p]])
        row, col, ok = grid.cell_of(xy)
        if not ok[0]:
            continue  # a peak outside the grid has no feature on it
        row, col, z = row[ok], col[ok], z[ok]
        # one generator per cell: the highest sample in it
        order = np.lexsort((-z, row * grid.nx + col))
        cell = (row * grid.nx + col)[order]
        first = np.r_[True, cell[1:] != cell[:-1]]
        out.append((row[order][first], col[order][first], z[order][first]))
    return out


def file_features(table, grid: Grid) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Generator cells ``(rows, cols, costs)`` per feature of a generator table (columns
    ``x, y, cost``, optional ``feature``; rows outside the grid dropped, the lowest cost kept
    per cell).

    Raises
    ------
    InputError : missing columns, non-finite values, negative costs, or no node on the grid.
    """
    cols = {str(c).strip().lower(): c for c in table.columns}
    missing = [c for c in ("x", "y", "cost") if c not in cols]
    if missing:
        raise InputError(f"the generators table lacks the column(s) {', '.join(missing)}; it needs x, y, cost "
                         "(and optionally feature)")
    xy = table[[cols["x"], cols["y"]]].to_numpy(float)
    c = table[cols["cost"]].to_numpy(float)
    fid = table[cols["feature"]].to_numpy() if "feature" in cols else np.arange(len(table))
    if not (np.isfinite(xy).all() and np.isfinite(c).all()):
        raise InputError("the generators table has non-finite x, y or cost values")
    if (c < 0).any():
        raise InputError("generator costs must be >= 0 (low cost = high ground)")
    row, col, ok = grid.cell_of(xy)
    if not ok.any():
        raise InputError("no generator of the table lies inside the grid; check its x, y against the extent")
    out = []
    for f in np.unique(fid[ok]):
        sel = ok & (fid == f)
        r, q, cc = row[sel], col[sel], c[sel]
        order = np.lexsort((cc, r * grid.nx + q))
        cell = (r * grid.nx + q)[order]
        first = np.r_[True, cell[1:] != cell[:-1]]
        out.append((r[order][first].astype(np.int64), q[order][first].astype(np.int64), cc[order][first]))
    return out


def river_cells(rivers, grid: Grid) -> np.ndarray:
    """uint8 mask of the grid cells the river edges cross (sampled every half cell)."""
    mask = np.zeros((grid.ny, grid.nx), np.uint8)
    if rivers is None or not rivers.n_nodes:
        return mask
    e = rivers.edges()
    if not e.size:
        return mask
    p0, p1 = rivers.xy[e[:, 0]], rivers.xy[e[:, 1]]
    n = np.maximum(np.ceil(np.hypot(*(p1 - p0).T) / (0.5 * grid.cell_size_m)).astype(np.int64), 1) + 1
    seg = np.repeat(np.arange(e.shape[0]), n)
    t = (np.arange(seg.size) - np.repeat(np.cumsum(n) - n, n)) / np.repeat(n - 1, n)
    row, col, ok = grid.cell_of(p0[seg] + t[:, None] * (p1[seg] - p0[seg]))
    mask[row[ok], col[ok]] = 1
    return mask


def secondary_paths(ca: np.ndarray, generator: np.ndarray, starts: np.ndarray) -> list[np.ndarray]:
    """Paths of flat cell indices from each start cell down the cost field ``ca`` to a
    generator cell (``generator`` bool mask): each step goes to the 8-neighbour of lowest
    cost, which is lower than the current one (Dijkstra fields with positive weights
    always have one), so every path is strictly decreasing and ends on a generator."""
    ny, nx = ca.shape
    out = []
    for s0 in starts:
        i, j = divmod(int(s0), nx)
        path = [i * nx + j]
        while not generator[i, j]:
            best, bi, bj = ca[i, j], -1, -1
            for di in (-1, 0, 1):
                for dj in (-1, 0, 1):
                    r, q = i + di, j + dj
                    if (di or dj) and 0 <= r < ny and 0 <= q < nx and ca[r, q] < best:
                        best, bi, bj = ca[r, q], r, q
            if bi < 0:
                break  # a local minimum that is not a generator (halted searches): stop here
            i, j = bi, bj
            path.append(i * nx + j)
        out.append(np.asarray(path, np.int64))
    return out


def blend(heights: np.ndarray, b: float) -> np.ndarray:
    """Eq. 2 over axis 0: ``sum h^(b+1) / sum h^b`` (0 where every height is 0).

    >>> float(blend(np.array([[1.0], [3.0]]), 0.0)[0])
    2.0
    """
    h = np.maximum(np.asarray(heights, float), 0.0)
    num = (h ** (b + 1)).sum(axis=0)
    den = (h ** b).sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)


def river_plain(rivers, grid: Grid, *, slope: float) -> np.ndarray:
    """The plain of ``sea_level=rivers`` before its cap: ``min over river cells (bed + slope x
    distance)`` (8-connected path lengths on ``grid``; beds linear between river nodes; +inf
    everywhere without a river cell on the grid).

    >>> from orokit.raster.rivers import RiverNetwork
    >>> from orokit.raster.rasterize import Grid
    >>> g = Grid(x0=0.0, y0=50.0, cell_size_m=10.0, ny=5, nx=5)
    >>> riv = RiverNetwork(xy=np.array([[5.0, 25.0], [45.0, 25.0]]), elevation=np.array([100.0, 100.0]),
    ...                    receiver=np.array([-1, 0]), length=np.array([0.0, 40.0]), order=np.array([0, 1]),
    ...                    outlet=np.array([True, False]))
    >>> p = river_plain(riv, g, slope=0.5)
    >>> float(p[2, 2]), float(p[0, 2])
    (100.0, 110.0)
    """
    h0 = np.full((grid.ny, grid.nx), np.inf)
    if rivers is not None and rivers.n_nodes:
        from orokit.generators.belhadj import _densify

        e = rivers.edges()
        if e.size:
            xy, h = _densify(rivers.xy[e[:, 0]], rivers.xy[e[:, 1]], rivers.elevation[e[:, 0]],
                             rivers.elevation[e[:, 1]], 0.5 * grid.cell_size_m)
            row, col, ok = grid.cell_of(xy)
            np.minimum.at(h0, (row[ok], col[ok]), h[ok])
    src = np.isfinite(h0)
    return spread(h0, src, grid, slope) if src.any() else h0


def generator_cap(gi: np.ndarray, gj: np.ndarray, cost: np.ndarray, top: float, grid: Grid, *,
                  slope: float) -> np.ndarray:
    """The cap of the ``sea_level=rivers`` plain: ``max over generator cells (top - cost - slope
    x distance)`` (8-connected path lengths on ``grid``).

    >>> from orokit.raster.rasterize import Grid
    >>> g = Grid(x0=0.0, y0=50.0, cell_size_m=10.0, ny=5, nx=5)
    >>> cap = generator_cap(np.array([2]), np.array([2]), np.array([0.0]), 100.0, g, slope=0.5)
    >>> float(cap[2, 2]), float(cap[2, 0])
    (100.0, 90.0)
    """
    h0 = np.full((grid.ny, grid.nx), np.inf)
    np.minimum.at(h0, (gi, gj), np.asarray(cost, float) - top)
    return -spread(h0, np.isfinite(h0), grid, slope)


def saddle_cap(feats, costs, top: float, grid: Grid) -> np.ndarray:
    """Per cell, the lowest generator elevation (its lowest saddle) of the feature owning the nearest
    generator cell (Euclidean): the plain stays below every feature's saddles, so it buries no peak.

    >>> from orokit.raster.rasterize import Grid
    >>> g = Grid(x0=0.0, y0=10.0, cell_size_m=1.0, ny=1, nx=6)
    >>> f = [(np.array([0, 0]), np.array([0, 1]), None), (np.array([0]), np.array([5]), None)]
    >>> saddle_cap(f, [np.array([0.0, 40.0]), np.array([10.0])], 100.0, g).tolist()
    [[60.0, 60.0, 60.0, 60.0, 90.0, 90.0]]
    """
    from scipy import ndimage

    low = np.full((grid.ny, grid.nx), np.nan)
    for (fi, fj, _), c in zip(feats, costs):
        low[fi, fj] = np.fmin(low[fi, fj], top - float(np.max(c)))
    _, (ii, jj) = ndimage.distance_transform_edt(np.isnan(low), return_indices=True)
    return low[ii, jj]



def learn(exemplar: xr.DataArray, grid: Grid, params: RusnellParams, rng: np.random.Generator
          ) -> tuple[np.ndarray, np.ndarray]:
    """The feature profile :func:`render` fits on ``exemplar`` (:func:`exemplar_profile`:
    distances and drops in metres); pass it back as ``render(..., learned=...)`` to render
    several trees without fitting again (same raster as fitting inside)."""
    return exemplar_profile(exemplar)


def render(tree, rivers, grid: Grid, rng: np.random.Generator, params: RusnellParams | None = None, *,
           exemplar: xr.DataArray | None = None, generators=None,
           learned: tuple[np.ndarray, np.ndarray] | None = None) -> xr.DataArray:
    """Elevation raster of a Divide Tree after Rusnell 2009, Algorithm 1 (pure: no file IO).

    Notes
    -----
    1. Graph: the 8-connected grid with edge weights ``(mu_w + r U[-1, 1])`` x step length.
    2. Generators: per peak, the cells of the peak and its half-ridges, cost = highest
       peak - elevation (or the ``generators`` table); sea level ``c_s = s x`` the largest
       generator cost, or (``sea_level`` exemplar / auto with an exemplar) highest peak - the
       exemplar's 1st-percentile elevation.
    3. Profile (``fit``): the exemplar's drop below the nearest peak against the distance,
       isotonic; w_s = profile slope / mu_w at ``c_m = (c - c_g) / (c_s - c_g) c_s`` (eq. 1).
    4. One search over all generators gives C_a; ``secondary`` random reached nodes send
       their least-cost path down C_a into the feature they reach (secondary ridges). Each
       feature's own search stops within 0.5 of c_s or where its height is below 5 % of
       C_a's height; with ``water`` every search halts at the river cells.
    5. Blend (eq. 2) with bias b; elevation = highest peak - c_s + blended height (cells no
       feature reaches are at ``highest peak - c_s``); from a table, ``c_s -`` blended cost.
    """
    params = params or RusnellParams()
    crs = check_crs(tree)
    if params.generators and generators is None:
        raise InputError(f"generators={params.generators!r} is a file the caller reads: pass "
                         "render_terrain(..., inputs={'generators': table}) (the CLI does it)")
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    if generators is not None:
        feats = file_features(generators, grid)
        costs = [f[2] for f in feats]
        top = None
    else:
        feats = features(tree, grid)
        if not feats:
            raise InputError("no peak of the Divide Tree lies inside the grid")
        top = max(float(f[2].max()) for f in feats)
        costs = [top - f[2] for f in feats]
    cmax = max(float(c.max()) for c in costs)
    cs = params.s * max(cmax, 1.0)
    sea = params.sea_level
    if sea == "auto":
        sea = ("preset" if exemplar is None or top is None
               else "rivers" if rivers is not None and rivers.n_nodes else "exemplar")
    if sea in ("exemplar", "rivers"):
        if exemplar is None or top is None:
            raise InputError(f"sea_level={sea} needs a Divide Tree and an exemplar DEM (CLI: --exemplar DEM)")
        if sea == "rivers" and (rivers is None or not rivers.n_nodes):
            raise InputError("sea_level=rivers needs the tree's rivers (none lie on the grid); use sea_level=exemplar")
        floor = float(np.nanquantile(np.asarray(exemplar.values, float), 0.01))
        cs = max(top - floor, 1.05 * max(cmax, 1.0))
    use_profile = params.profile == "fit"
    if use_profile:
        if learned is None:
            if exemplar is None:
                raise InputError("generator rusnell with profile=fit needs an exemplar DEM (CLI: --exemplar DEM), "
                                 "or --param profile=none")
            learned = learn(exemplar, grid, params, rng)
        d, h = learned
        table = slope_table(d, h, cs, params.mu_w)
    else:
        table = np.ones(2)
    timings["profile"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    w = edge_weights(grid.ny, grid.nx, params.mu_w, params.r, rng, cell_m=grid.cell_size_m)
    ny, nx = grid.ny, grid.nx
    stop = river_cells(rivers, grid) if params.water else np.zeros((0, 0), np.uint8)
    stamp = np.full((ny, nx), -1, np.int32)
    fixed = np.full((ny, nx), -1, np.int32)
    cost = np.zeros((ny, nx))
    src = np.zeros((ny, nx))
    touched = np.empty(ny * nx, np.int64)
    gi = np.concatenate([f[0] for f in feats])
    gj = np.concatenate([f[1] for f in feats])
    gc = np.concatenate(costs)
    _k.cost_field(w, gi, gj, gc, cs, table, use_profile, np.zeros((0, 0)), 0.0, stamp, 0, cost, src, touched, fixed,
                  stop)
    ca = np.where(stamp == 0, cost, cs)
    timings["all_generators"] = time.perf_counter() - t0
    if params.secondary:
        t0 = time.perf_counter()
        owner = np.full((ny, nx), -1, np.int64)
        for f, (fi, fj, _) in enumerate(feats):
            owner[fi, fj] = f
        reached = np.flatnonzero(((stamp == 0) & (ca < cs) & (owner < 0)).ravel())
        starts = rng.choice(reached, size=min(params.secondary, reached.size), replace=False) if reached.size \
            else np.zeros(0, np.int64)
        feats = [(fi, fj, c) for (fi, fj, _), c in zip(feats, costs)]
        for path in secondary_paths(ca, owner >= 0, starts):
            end = owner.ravel()[path[-1]]
            if end < 0:
                continue
            new = path[owner.ravel()[path] < 0]
            fi, fj, c = feats[end]
            cg = ca.ravel()[path[-1]]
            feats[end] = (np.concatenate([fi, new // nx]), np.concatenate([fj, new % nx]),
                          np.concatenate([c, cg + params.secondary_scale * (ca.ravel()[new] - cg)]))
            owner.ravel()[new] = end
        costs = [f[2] for f in feats]
        timings["secondary"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    num = np.zeros((ny, nx))
    den = np.zeros((ny, nx))
    for f, (fi, fj, _), c in zip(range(len(feats)), feats, costs):
        m = _k.cost_field(w, fi, fj, c, cs, table, use_profile, ca, HALT_FRACTION, stamp, f + 1, cost, src,
                          touched, fixed, stop)
        _k.blend_add(touched, m, cost, cs, float(params.b), num, den)
    hf = np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)
    timings["features"] = time.perf_counter() - t0
    z = (top - cs + hf) if top is not None else hf
    if sea == "rivers":
        assert exemplar is not None and top is not None  # "rivers" needs both (checked above)
        t0 = time.perf_counter()
        fi = np.concatenate([f[0] for f in feats])
        fj = np.concatenate([f[1] for f in feats])
        fc = np.concatenate(costs)
        slope = exemplar_slope(exemplar)
        steep = slope if math.isnan(params.cap_quantile) else exemplar_slope(exemplar, quantile=params.cap_quantile)
        plain = np.minimum(river_plain(rivers, grid, slope=slope), generator_cap(fi, fj, fc, top, grid, slope=steep))
        if params.saddle_cap:
            plain = np.minimum(plain, saddle_cap(feats, costs, top, grid))
        plain[fi, fj] = -np.inf  # generator cells keep their elevation
        z = np.maximum(z, plain)
        timings["plain"] = time.perf_counter() - t0
    z = z.astype(np.float32)
    logger.info("rusnell: %d features, c_s %.0f m, %s profile", len(feats), cs, params.profile)
    return as_dataarray(z, grid, crs, {"timings": timings})
