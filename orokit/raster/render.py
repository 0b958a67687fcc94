"""Terrain from a Divide Tree (Argudo et al. 2019, §6): rivers, TIN, raster, noise, erosion.

:func:`render_elevation` turns a :class:`~orokit.topology.divide_tree.DivideTree` into a
georeferenced elevation raster whose peaks, saddles and ridges are those of the tree;
:func:`write_cog`, :func:`write_hillshade_png` and :func:`write_tin_ply` write it.
"""
from __future__ import annotations

import json
import logging
import math
import time
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import rioxarray  # noqa: F401 - registers the .rio accessor
import xarray as xr
from scipy import ndimage

from orokit import __version__
from orokit._typing import PathLike, SeedLike
from orokit.errors import CRSError, DivideTreeError, InputError, OrokitWarning
from orokit.raster import _kernels
from orokit.raster.erosion import erode_multiscale
from orokit.raster.interpolate import flank_envelope, poisson_samples, sample_elevation, valley_width
from orokit.raster.noise import falloff, fractal_noise
from orokit.raster.rasterize import MAX_CELLS, Grid, burn_max, make_grid, rasterize_tin, set_cells
from orokit.raster.refine import Polylines, densify, refine_segments
from orokit.raster.rivers import RidgeSegments, RiverNetwork, ridge_segments, river_network
from orokit.raster.tin import TIN, constrained_tin
from orokit.topology import _kernels as _engine

logger = logging.getLogger(__name__)

__all__ = [
    "RenderParams", "TerrainSkeleton", "build_skeleton", "render_elevation", "tree_extent",
    "write_cog", "write_hillshade_png", "write_tin_ply", "resolve_seed",
]


@dataclass(frozen=True)
class RenderParams:
    """Parameters of the renderer (metres unless stated).

    lam : meshing distance lambda (ridge/river pieces and Poisson-disk radius).
    jitter : planar jitter of refined points, as a fraction of the piece length.
    river_slope : minimum downstream slope of river beds (m/m).
    river_margin : river beds lie at least this far below the ridges they face.
    valley_coef : valley width ``w = valley_coef * A^0.4`` (A in m^2).
    min_prominence : eps of the orometry to keep; noise amplitude is ``noise_ratio * eps``.
    noise_ratio : noise amplitude as a fraction of eps (< 0.5 so no new peak reaches eps).
    uplift_radius : R of the compensating uplift and noise mask around peaks and saddles.
    erosion_scales : grid spacings of the erosion passes.
    erosion_steps : erosion + uplift iterations per scale (one number or one per scale; fewer at the
        fine, expensive scales).
    erosion_k_dt : stream-power K * dt.
    erosion_max_nodes : largest erosion grid (finer scales run coarser; bounds memory).
    flank_slope, flank_ratio : flanks fall at least ``max(flank_slope, flank_ratio * ridge slope)``
        from every ridge point (keeps saddles the highest passes).
    """

    lam: float = 200.0
    jitter: float = 0.25
    river_slope: float = 0.01
    river_margin: float = 5.0
    valley_coef: float = 0.15
    min_prominence: float = 30.0
    noise_ratio: float = 0.3
    uplift_radius: float = 1500.0
    erosion_scales: tuple[float, ...] = (100.0, 50.0, 30.0)
    erosion_steps: int | tuple[int, ...] = (4, 3, 2)
    erosion_k_dt: float = 0.02
    erosion_max_nodes: int = 4_000_000
    flank_slope: float = 0.15
    flank_ratio: float = 1.5

    def to_dict(self) -> dict[str, Any]:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.__dict__.items()}


@dataclass(frozen=True)
class TerrainSkeleton:
    """Sparse intermediate products: refined ridges and rivers, river forest and TIN."""

    ridges: Polylines
    rivers: Polylines
    river_network: RiverNetwork
    tin: TIN
    extent: tuple[float, float, float, float]
    node_xyz: np.ndarray  # peaks then used saddles (x, y, z)
    n_peaks: int
    timings: dict[str, float] = field(default_factory=dict)
    piece_saddle: np.ndarray | None = None  # saddle (0..m-1) of each straight ridge piece
    edges: np.ndarray | None = None  # (m, 3) peak_a, peak_b, saddle (0..m-1, rows of node_xyz after the peaks)


def resolve_seed(rng: SeedLike | np.random.SeedSequence) -> int:
    """The int seed a render runs with, so it can be recorded and replayed.

    An int is kept; ``None`` draws fresh entropy (``np.random.SeedSequence().entropy``);
    a Generator or SeedSequence yields an int drawn from it (deterministic for a seeded
    one). ``np.random.default_rng(resolve_seed(rng))`` then drives the whole render, so
    rendering again with the recorded seed gives the same raster.

    Examples
    --------
    >>> resolve_seed(7)
    7
    >>> resolve_seed(np.random.default_rng(0)) == resolve_seed(np.random.default_rng(0))
    True
    """
    if rng is None:
        return int(np.random.SeedSequence().entropy)
    if isinstance(rng, (int, np.integer)) and not isinstance(rng, (bool, np.bool_)):
        if int(rng) < 0:
            raise InputError(f"seed must be a non-negative integer, got {int(rng)}")
        return int(rng)
    if isinstance(rng, np.random.SeedSequence):
        lo, hi = (int(v) for v in rng.generate_state(2, np.uint64))
        return lo + (hi << 64)
    if isinstance(rng, np.random.Generator):
        return int(rng.integers(0, 2**63 - 1))
    raise InputError(f"rng must be an int seed, a numpy Generator, a SeedSequence or None, got {type(rng).__name__}")


def _tree_arrays(tree) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Peaks (n, 3), used saddles (m, 3) and edges (m, 3) with renumbered saddles."""
    if tree.n_peaks == 0:
        raise DivideTreeError("the Divide Tree has no peaks; nothing to render")
    tree.validate()
    p = tree.peaks[["x", "y", "elevation"]].to_numpy(float)
    s = tree.saddles[["x", "y", "elevation"]].to_numpy(float)
    e = tree.edges[["peak_a", "peak_b", "saddle"]].to_numpy(np.int64).reshape(-1, 3)
    if not np.isfinite(p).all() or (s.size and not np.isfinite(s[np.unique(e[:, 2])]).all()):
        raise DivideTreeError("the Divide Tree has non-finite peak or saddle coordinates/elevations; fix or drop them")
    used = np.unique(e[:, 2])
    remap = np.full(max(s.shape[0], 1), -1, np.int64)
    remap[used] = np.arange(used.size)
    e = e.copy()
    e[:, 2] = remap[e[:, 2]] if e.size else e[:, 2]
    return p, s[used].reshape(-1, 3), e


def _check_crs(tree) -> Any:
    crs = tree.crs
    if crs is None:
        return None
    from pyproj import CRS

    crs = CRS.from_user_input(crs)
    if crs.is_geographic:
        raise CRSError(
            f"the Divide Tree is in a geographic CRS ({crs.name}); rendering needs metres: "
            "reproject the tree to a projected CRS (e.g. its UTM zone) first"
        )
    return crs


def tree_extent(tree, *, pad_m: float | None = None) -> tuple[float, float, float, float]:
    """Extent ``(xmin, ymin, xmax, ymax)`` of a tree: ``attrs['extent']``, the synthesis
    ``attrs['domain']`` (x0, y0 = south-west corner, width, height), else the bounding
    box of its peaks and saddles padded by ``pad_m`` (default 5 %, at least 1 km)."""
    attrs = tree.attrs if isinstance(tree.attrs, dict) else {}
    if attrs.get("extent") is not None:
        return tuple(float(v) for v in attrs["extent"])  # type: ignore[return-value]
    dom = attrs.get("domain")
    if isinstance(dom, dict) and {"x0", "y0", "width", "height"} <= set(dom):
        x0, y0 = float(dom["x0"]), float(dom["y0"])
        return (x0, y0, x0 + float(dom["width"]), y0 + float(dom["height"]))
    xy = np.concatenate([tree.peaks[["x", "y"]].to_numpy(float), tree.saddles[["x", "y"]].to_numpy(float)])
    xmin, ymin = xy.min(axis=0)
    xmax, ymax = xy.max(axis=0)
    span = max(xmax - xmin, ymax - ymin)
    pad = pad_m if pad_m is not None else max(1000.0, 0.05 * span)
    return (float(xmin - pad), float(ymin - pad), float(xmax + pad), float(ymax + pad))


def separate_saddles(p: np.ndarray, s: np.ndarray, e: np.ndarray, clearance_m: float) -> np.ndarray:
    """Saddle positions moved along their ridge so each is ``clearance_m`` from both peaks.

    A saddle closer than ``clearance_m`` to one of its two peaks (e.g. in the same raster
    cell, where it would overwrite the peak) slides along the straight peak-peak line,
    keeping its sideways offset, to ``clearance_m`` from the nearer end, or to the middle
    when the ridge is shorter than twice that. Elevations (hence the orometry) are kept.
    """
    s = s.copy()
    if clearance_m <= 0 or not e.size:
        return s
    pa, pb, ps = p[e[:, 0], :2], p[e[:, 1], :2], s[e[:, 2], :2]
    d = pb - pa
    length = np.hypot(d[:, 0], d[:, 1])
    close = (np.hypot(*(ps - pa).T) < clearance_m) | (np.hypot(*(ps - pb).T) < clearance_m)
    close &= length > 0
    if not close.any():
        return s
    u = d[close] / length[close, None]
    rel = ps[close] - pa[close]
    t = rel[:, 0] * u[:, 0] + rel[:, 1] * u[:, 1]
    side = rel - t[:, None] * u
    L = length[close]
    lo = np.minimum(clearance_m, 0.5 * L)
    t = np.clip(t, lo, L - lo)
    # the sideways offset may not bring the saddle back within the clearance
    side *= np.clip(np.minimum(t, L - t) / np.maximum(np.hypot(side[:, 0], side[:, 1]), 1e-9), 0.0, 1.0)[:, None] * 0.5
    s[e[close, 2], :2] = pa[close] + t[:, None] * u + side
    logger.debug("moved %d saddles away from their peaks (clearance %.0f m)", int(close.sum()), clearance_m)
    return s


def build_skeleton(
    tree, *, extent: tuple[float, float, float, float], params: RenderParams = RenderParams(),
    saddle_clearance_m: float = 0.0, rng: SeedLike = None
) -> TerrainSkeleton:
    """Rivers, refined ridges and rivers, Poisson samples with elevations and the TIN.

    Notes
    -----
    1. Rivers: :func:`orokit.raster.rivers.river_network` on the peaks and saddles.
    2. Ridges and rivers are refined to pieces shorter than ``lam`` with jitter.
    3. Poisson-disk samples at radius ``lam`` over the extent (padded by ``lam``), minus
       those closer than ``lam / 2`` to a ridge or river; each gets its elevation from
       the nearest ridge and river points with valley width ``w ~ A^0.4``.
    4. Constrained Delaunay TIN of all points keeping ridge and river pieces.

    Saddles closer than ``saddle_clearance_m`` to one of their peaks are first moved
    along their ridge (:func:`separate_saddles`; ``render_elevation`` uses 1.5 cells).
    """
    rng = np.random.default_rng(rng)
    t = {}
    t0 = time.perf_counter()
    p, s, e = _tree_arrays(tree)
    s = separate_saddles(p, s, e, saddle_clearance_m)
    n = p.shape[0]
    nodes = np.concatenate([p, s])
    lam = float(params.lam)
    ridges = ridge_segments(p, s, e)
    zmin = float(nodes[:, 2].min())
    eps = float(params.min_prominence)
    base = zmin - max(eps, params.river_margin)
    if zmin >= 0 > base:
        base = 0.5 * zmin
    ridge_lines = refine_segments(nodes[:, :2], nodes[:, 2], np.column_stack([ridges.node0, ridges.node1]),
                                  lam=lam, jitter=params.jitter, rng=rng)
    t["refine"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    # rivers run on the medial axis between the refined ridges (Voronoi of all ridge points)
    fine = ridge_lines.segments
    fine_ridges = RidgeSegments(ridge_lines.xy[fine[:, 0]], ridge_lines.xy[fine[:, 1]],
                                ridge_lines.z[fine[:, 0]], ridge_lines.z[fine[:, 1]], fine[:, 0], fine[:, 1])
    rxy, rz, rs = densify(ridge_lines, lam / 4.0, value="slope")
    rs = np.maximum(params.flank_slope, params.flank_ratio * rs)
    from scipy.spatial import cKDTree

    rtree = cKDTree(rxy)

    def envelope(xy: np.ndarray) -> np.ndarray:
        return flank_envelope(xy, rxy, rz, rs, tree=rtree)

    rivers = river_network(fine_ridges, ridge_lines.xy, extent, base_elevation=base,
                           margin_m=params.river_margin, slope=params.river_slope, cap=envelope)
    t["rivers"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    xmin, ymin, xmax, ymax = extent
    pext = (xmin - lam, ymin - lam, xmax + lam, ymax + lam)
    samples = poisson_samples(pext, lam, rng=rng)
    # boundary ring so the TIN covers the padded extent
    bx = np.linspace(pext[0], pext[2], max(int(np.ceil((pext[2] - pext[0]) / lam)), 1) + 1)
    by = np.linspace(pext[1], pext[3], max(int(np.ceil((pext[3] - pext[1]) / lam)), 1) + 1)
    ring = np.concatenate([
        np.column_stack([bx, np.full_like(bx, pext[1])]), np.column_stack([bx, np.full_like(bx, pext[3])]),
        np.column_stack([np.full_like(by[1:-1], pext[0]), by[1:-1]]),
        np.column_stack([np.full_like(by[1:-1], pext[2]), by[1:-1]]),
    ])
    # drainage area: each sample's area goes to its nearest river node
    cell_area = (pext[2] - pext[0]) * (pext[3] - pext[1]) / max(samples.shape[0], 1)
    _, near = cKDTree(rivers.xy).query(samples)
    local = np.bincount(near, minlength=rivers.n_nodes) * cell_area
    area = rivers.drainage_area(local)
    river_seg = rivers.edges()
    river_lines = refine_segments(rivers.xy, rivers.elevation, river_seg, lam=lam, jitter=params.jitter,
                                  node_a=area, rng=rng)
    t["refine"] += time.perf_counter() - t0

    t0 = time.perf_counter()
    dense = lam / 4.0
    vxy, vz, va = densify(river_lines, dense) if river_seg.size else (rivers.xy, rivers.elevation, area)
    pts = np.concatenate([samples, ring])
    h, dT, dR = sample_elevation(pts, rxy, rz, vxy, vz, valley_width(va, coef=params.valley_coef), ridge_slope=rs)
    far = (np.minimum(dT, dR) >= 0.5 * lam)
    far[samples.shape[0]:] = True  # keep the ring
    pts, h = pts[far], h[far]
    t["samples"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    nr = ridge_lines.xy.shape[0]
    nv = river_lines.xy.shape[0]
    xy = np.concatenate([ridge_lines.xy, river_lines.xy, pts])
    z = np.concatenate([ridge_lines.z, river_lines.z, h])
    segs = np.concatenate([ridge_lines.segments, river_lines.segments + nr]) if nv else ridge_lines.segments
    tin = constrained_tin(xy, z, segs)
    t["tin"] = time.perf_counter() - t0
    logger.info("skeleton: %d ridge pts, %d river pts, %d samples, %d triangles",
                nr, nv, pts.shape[0], tin.n_triangles)
    return TerrainSkeleton(ridge_lines, river_lines, rivers, tin, extent, nodes, n, t, ridges.node1 - n, e)


def render_elevation(
    divide_tree,
    *,
    resolution_m: float,
    extent: tuple[float, float, float, float] | None = None,
    erosion: bool = True,
    params: RenderParams | None = None,
    max_cells: int = MAX_CELLS,
    return_skeleton: bool = False,
    rng: SeedLike = None,
):
    """Elevation raster of a Divide Tree.

    Parameters
    ----------
    divide_tree : DivideTree in a projected CRS or a local metric frame (x, y, elevation in metres).
    resolution_m : cell size of the output in metres.
    extent : ``(xmin, ymin, xmax, ymax)`` in the tree's CRS; default :func:`tree_extent`.
    erosion : run the multi-scale constrained erosion.
    params : :class:`RenderParams` (lambda, noise, erosion...).
    max_cells : refuse rasters larger than this (checked before allocating).
    return_skeleton : also return the :class:`TerrainSkeleton` (TIN, rivers...).
    rng : seed, Generator, SeedSequence or None; the int seed actually used
        (:func:`resolve_seed`: fresh entropy for None) is recorded in ``attrs['seed']``,
        and the same seed gives the same raster.

    Returns
    -------
    DataArray (dims y, x; float32 metres; NaN nodata; CRS and transform through
    rioxarray; attrs ``units``, ``generator``, ``parameters``, ``seed``, ``timings``...),
    or ``(DataArray, TerrainSkeleton)`` with ``return_skeleton``.

    Raises
    ------
    InputError : bad resolution or extent (zero, negative, too large), no peak inside the extent.
    CRSError : the tree is in a geographic CRS.
    DivideTreeError : empty or malformed tree.

    Notes
    -----
    1. Skeleton (:func:`build_skeleton`): dual rivers, refinement, Poisson samples, TIN.
    2. Barycentric rasterization of the TIN at cell centres; ridge pieces are burnt in
       (cells raised to the ridge elevation), then peak and saddle cells are set to
       their exact elevation so the raster's highest paths follow the ridges.
    3. Multi-fractal noise of amplitude ``noise_ratio * eps``, masked by
       ``1 - g(d / R)`` around peaks and saddles (g = (1 - r^2)^3).
    4. Erosion (optional): fastscapelib stream power at 100, 50, 30 m with
       compensating uplift ``U = g(d / R)``.
    5. Peak and saddle cells are reset to their exact elevations.
    """
    params = params or RenderParams()
    seed = resolve_seed(rng)
    rng = np.random.default_rng(seed)
    crs = _check_crs(divide_tree)
    if divide_tree.n_peaks == 0:
        raise DivideTreeError("the Divide Tree has no peaks; nothing to render")
    ext = tuple(float(v) for v in extent) if extent is not None else tree_extent(divide_tree)
    grid = make_grid(ext, resolution_m, max_cells=max_cells)  # errors before any allocation
    pxy = divide_tree.peaks[["x", "y"]].to_numpy(float)
    inside = (pxy[:, 0] >= ext[0]) & (pxy[:, 0] <= ext[2]) & (pxy[:, 1] >= ext[1]) & (pxy[:, 1] <= ext[3])
    if not inside.any():
        raise InputError(
            f"no peak of the Divide Tree lies inside the extent {ext}; the tree spans "
            f"x {pxy[:, 0].min():.6g}..{pxy[:, 0].max():.6g}, y {pxy[:, 1].min():.6g}..{pxy[:, 1].max():.6g} "
            "(check the CRS or pass an extent that covers the tree)"
        )
    if not inside.all():
        warnings.warn(f"{int((~inside).sum())} of {inside.size} peaks lie outside the extent and are cut off",
                      OrokitWarning, stacklevel=2)

    skel = build_skeleton(divide_tree, extent=ext, params=params, saddle_clearance_m=1.5 * grid.res, rng=rng)
    timings = dict(skel.timings)

    t0 = time.perf_counter()
    z = rasterize_tin(skel.tin, grid)
    rxy, rz, _, rorig = densify(skel.ridges, 0.5 * grid.res, origin=True)
    burn_max(z, grid, rxy, rz)
    label = np.full(z.shape, -1, np.int32)  # saddle of the ridge of every burnt cell
    row, col, ok = grid.cell_of(rxy)
    ok &= rorig >= 0
    if skel.piece_saddle is not None and skel.piece_saddle.size:
        label[row[ok], col[ok]] = skel.piece_saddle[rorig[ok]].astype(np.int32)
    nodes = skel.node_xyz
    set_cells(z, grid, nodes[:, :2], nodes[:, 2])
    if np.isnan(z).any():
        z = np.where(np.isnan(z), np.float32(np.nanmin(z)), z)
    timings["raster"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    mask = np.ones(z.shape, bool)
    row, col, ok = grid.cell_of(nodes[:, :2])
    mask[row[ok], col[ok]] = False
    dist = ndimage.distance_transform_edt(mask, sampling=grid.res).astype(np.float32)
    uplift = falloff(dist / np.float32(params.uplift_radius))
    del dist, mask
    amp = params.noise_ratio * params.min_prominence
    if amp > 0:
        zmin, zmax = float(z.min()), float(z.max())
        rough = (z - zmin) / max(zmax - zmin, 1e-6)
        z += fractal_noise(z.shape, grid.res, amplitude=amp, roughness=rough, rng=rng) * (1.0 - uplift)
        del rough
    timings["noise"] = time.perf_counter() - t0

    if erosion:
        t0 = time.perf_counter()
        z = erode_multiscale(z, grid.res, uplift, scales_m=params.erosion_scales,
                             steps=params.erosion_steps, k_dt=params.erosion_k_dt,
                             max_nodes=params.erosion_max_nodes)
        timings["erosion"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    set_cells(z, grid, nodes[:, :2], nodes[:, 2])
    enforce_orometry(z, grid, skel, label=label)
    timings["orometry"] = time.perf_counter() - t0

    x, y = grid.centres()
    da = xr.DataArray(z.astype(np.float32, copy=False), dims=("y", "x"), coords={"y": y, "x": x}, name="elevation")
    from affine import Affine

    if crs is not None:
        da = da.rio.write_crs(crs)
    da = da.rio.write_transform(Affine(grid.res, 0.0, grid.x0, 0.0, -grid.res, grid.y0))
    da.attrs.update({
        "units": "m",
        "generator": "orokit.raster.render_elevation (Argudo et al. 2019, section 6)",
        "orokit_version": __version__,
        "parameters": json.dumps({**params.to_dict(), "resolution_m": grid.res, "extent": list(ext),
                                  "erosion": bool(erosion)}),
        "seed": seed,
        "local_grid": crs is None,
        "cell_size": grid.res,
        "n_tree_peaks": int(divide_tree.n_peaks),
        "timings": json.dumps({k: round(v, 3) for k, v in timings.items()}),
    })
    logger.info("rendered %d x %d at %g m in %.2f s", grid.nx, grid.ny, grid.res, sum(timings.values()))
    return (da, skel) if return_skeleton else da


def _saddle_normals(skel: TerrainSkeleton) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals of the ridge at every saddle (from its two refined neighbours)."""
    n = skel.n_peaks
    m = skel.node_xyz.shape[0] - n
    seg = skel.ridges.segments
    xy = skel.ridges.xy
    nb = np.full((m, 2), -1, np.int64)
    sid = np.concatenate([seg[:, 0], seg[:, 1]])
    other = np.concatenate([seg[:, 1], seg[:, 0]])
    is_s = (sid >= n) & (sid < n + m)
    sid, other = sid[is_s] - n, other[is_s]
    order = np.argsort(sid, kind="stable")
    sid, other = sid[order], other[order]
    if sid.size:
        first = np.r_[True, sid[1:] != sid[:-1]]
        last = np.r_[sid[1:] != sid[:-1], True]
        nb[sid[first], 0] = other[first]
        nb[sid[last], 1] = other[last]
    sxy = skel.node_xyz[n:, :2]
    p0 = np.where(nb[:, :1] >= 0, xy[np.maximum(nb[:, 0], 0)], sxy)
    p1 = np.where(nb[:, 1:] >= 0, xy[np.maximum(nb[:, 1], 0)], sxy)
    d = p1 - p0
    norm = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-12)
    return -d[:, 1] / norm, d[:, 0] / norm


def enforce_orometry(z: np.ndarray, grid: Grid, skel: TerrainSkeleton, *, label: np.ndarray | None = None,
                     drop_m: float = 0.5, trench_m: float = 3000.0, max_rounds: int = 6) -> np.ndarray:
    """Make the raster's orometry that of the tree (in place).

    1. A trench perpendicular to the ridge through every saddle, just below it, until the
       ground is lower (no path beside a saddle crosses the ridge above it); a trench
       stops at a cell of another ridge (``label``: tree edge id of burnt ridge cells).
    2. Peak and saddle cells get their exact elevations.
    3. Rounds of basin checks (:func:`cap_basins`): hills without a tree peak are cut
       down to their pass with a strictly ascending path (1 mm per cell) to a tree peak,
       and every pass between the basins of two tree peaks that is higher than the
       tree's bottleneck between them (the lowest saddle on the tree path) is lowered
       ``drop_m`` below it, so the raster's Divide Tree is the tree.
    """
    n = skel.n_peaks
    nodes = skel.node_xyz
    if nodes.shape[0] > n:
        nxv, nyv = _saddle_normals(skel)
        s = nodes[n:]
        _kernels.carve_saddles(z, float(grid.x0), float(grid.y0), float(grid.res),
                               np.ascontiguousarray(s[:, 0]), np.ascontiguousarray(s[:, 1]),
                               np.ascontiguousarray(s[:, 2]), nxv, nyv, float(trench_m), float(drop_m),
                               label if label is not None else np.full(z.shape, -1, np.int32))
    set_cells(z, grid, nodes[:, :2], nodes[:, 2])
    # ridge cells may be lowered down to their own saddle, peak and saddle cells never
    floor = np.full(z.shape, -np.inf, np.float32)
    if label is not None and nodes.shape[0] > n:
        on = label >= 0
        floor[on] = nodes[n + label[on], 2]
    row, col, ok = grid.cell_of(nodes[:, :2])
    floor[row[ok], col[ok]] = np.inf
    cap_basins(z, grid, skel, floor=floor, drop_m=drop_m, max_rounds=max_rounds)
    set_cells(z, grid, nodes[:, :2], nodes[:, 2])
    return z


def _border_pairs(owner: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Flat indices ``(a, b)`` of 8-adjacent cells whose ``owner`` differs (both >= 0)."""
    ny, nx = owner.shape
    ia, ib = [], []
    idx = np.arange(ny * nx, dtype=np.int64).reshape(ny, nx)
    for dr, dc in ((0, 1), (1, -1), (1, 0), (1, 1)):
        a = (slice(0, ny - dr), slice(max(0, -dc), nx - max(0, dc)))
        b = (slice(dr, ny), slice(max(0, dc), nx - max(0, -dc)))
        oa, ob = owner[a], owner[b]
        m = (oa != ob) & (oa >= 0) & (ob >= 0)
        ia.append(idx[a][m])
        ib.append(idx[b][m])
    return np.concatenate(ia), np.concatenate(ib)


def cap_basins(z: np.ndarray, grid: Grid, skel: TerrainSkeleton, *, floor: np.ndarray, drop_m: float = 0.5,
               max_rounds: int = 6) -> dict[str, int]:
    """Rounds of spurious-hill cutting and pass capping on the raster's own basins (in place).

    Each round labels the basins of steepest ascent with the orometry engine's own
    kernels (:func:`orokit.topology._kernels.steepest_ascent` and ``label_basins``, so
    the total order and tie-breaks are the engine's); basins whose maximum is not a tree peak are cut down (flooded from their
    outside with a 1 mm per cell ascent); then every pair of 8-adjacent cells in the
    basins of two tree peaks whose pass (the lower of the two) is above the tree's
    bottleneck between the peaks (lowest saddle on the tree path) is lowered ``drop_m``
    below it: the lower cell, or the higher one when the target is below the lower
    cell's ``floor`` (a ridge cell's own saddle elevation, +inf at peaks and saddles).
    Stops when a round changes nothing. ``z`` must be C-contiguous. Returns counters
    (rounds, cells cut, cells capped, border pairs left above their bottleneck).
    """
    if not z.flags.c_contiguous:
        raise ValueError("cap_basins works in place on a C-contiguous array; pass np.ascontiguousarray(z)")
    n = skel.n_peaks
    nodes = skel.node_xyz
    e = skel.edges if skel.edges is not None else np.empty((0, 3), np.int64)
    parent, height, depth = _kernels.merge_tree(
        n, e[:, 0].astype(np.int64), e[:, 1].astype(np.int64),
        nodes[n + e[:, 2], 2].astype(np.float64) if e.size else np.empty(0))
    row, col, ok = grid.cell_of(nodes[:n, :2])
    pid = np.flatnonzero(ok)
    pid = pid[np.argsort(nodes[pid, 2], kind="stable")]  # the highest peak of a shared cell wins
    cells = row[pid] * grid.nx + col[pid]
    order = np.argsort(cells, kind="stable")
    cells, pid = cells[order], pid[order]
    last = np.r_[cells[1:] != cells[:-1], True] if cells.size else np.zeros(0, bool)
    cells, pid = cells[last], pid[last]
    zf = z.reshape(-1)
    ff = floor.reshape(-1)
    stats = {"rounds": 0, "cut": 0, "capped": 0, "left": 0}

    if cells.size == 0:
        return stats

    def owners() -> np.ndarray:
        """Tree peak owning each cell's basin (-1: a spurious maximum, -2: NaN)."""
        ptr, _ = _engine.steepest_ascent(np.pad(z, 1, constant_values=np.nan))
        lab, peak_cell = _engine.label_basins(ptr)
        k = np.minimum(np.searchsorted(cells, peak_cell), cells.size - 1)
        tid = np.where(cells[k] == peak_cell, pid[k], -1)
        return np.where(lab >= 0, tid[np.maximum(lab, 0)], -2).reshape(z.shape)

    for _ in range(max_rounds):
        stats["rounds"] += 1
        own = owners()
        cut = 0
        spurious = own == -1
        spurious.reshape(-1)[cells] = False  # tree peaks seed the flood, never lowered
        if spurious.any():
            cut = _kernels.reconstruct_masked(z, spurious, 1e-3)
            stats["cut"] += cut
            own = owners()
        ia, ib = _border_pairs(own)
        ta, tb = own.reshape(-1)[ia], own.reshape(-1)[ib]
        lo, hi = np.minimum(ta, tb), np.maximum(ta, tb)
        keys, inv = np.unique(lo * n + hi, return_inverse=True)
        bn = _kernels.bottlenecks(parent, height, depth, keys // n, keys % n)[inv.ravel()]
        za, zb = zf[ia].astype(np.float64), zf[ib].astype(np.float64)
        viol = (np.minimum(za, zb) > bn + 1e-3) & np.isfinite(bn)  # -inf: peaks of separate trees
        stats["left"] = int(viol.sum())
        if not viol.any():
            break
        ia, ib, za, zb, target = ia[viol], ib[viol], za[viol], zb[viol], bn[viol] - drop_m
        low = np.where(za <= zb, ia, ib)
        high = np.where(za <= zb, ib, ia)
        # a cell may go down to max(target, its floor) if that floor is not above the bottleneck
        # (ridge cells of the saddle itself end at the saddle's height: a tie, not a bypass)
        lim = (bn[viol] + 1e-4).astype(zf.dtype)
        pick = np.where(ff[low] <= lim, low, np.where(ff[high] <= lim, high, -1))
        keep = pick >= 0
        pick = pick[keep]
        np.minimum.at(zf, pick, np.maximum(target[keep].astype(zf.dtype), ff[pick]))
        stats["capped"] += int(keep.sum())
        if not keep.any() and cut == 0:
            break
    logger.debug("basin capping: %s", stats)
    return stats


# ----------------------------------------------------------------------------- writers
def write_cog(dem: xr.DataArray, path: PathLike, *, tags: dict[str, Any] | None = None) -> None:
    """Write ``dem`` as a Cloud-Optimized GeoTIFF (deflate, NaN nodata) with provenance tags.

    The band's unit is set to ``dem.attrs['units']`` (metres), so
    :func:`orokit.io.dem.read_dem` (and ``orokit analyze`` / ``classify``) read the file
    without ``z_units``, also when it has no CRS (a local metric grid: the transform is
    kept). The CRS is written when ``dem`` has one. Dataset tags: units, generator,
    orokit version, parameters, seed, local_grid, timings, plus ``tags``. Written
    atomically (temporary file beside ``path``, then renamed).
    """
    import rasterio

    from orokit.io.atomic import atomic_path

    units = str(dem.attrs.get("units", "m"))
    if units != "m":
        raise InputError(f"write_cog writes elevations in metres; the raster's units are {units!r}")
    all_tags = {k: str(v) for k, v in dem.attrs.items() if k in (
        "units", "generator", "orokit_version", "parameters", "seed", "local_grid", "timings")}
    all_tags.update({k: str(v) for k, v in (tags or {}).items()})
    z = np.asarray(dem.values, dtype=np.float32)
    if z.ndim != 2:
        raise InputError(f"write_cog writes one 2-D band; got an array of shape {z.shape}")
    profile = {"driver": "COG", "width": z.shape[1], "height": z.shape[0], "count": 1, "dtype": "float32",
               "crs": dem.rio.crs, "transform": dem.rio.transform(), "nodata": np.nan,
               "compress": "DEFLATE", "predictor": 3}
    with atomic_path(path) as tmp:
        with rasterio.open(tmp, "w", **profile) as dst:
            dst.write(z, 1)
            dst.units = ("m",)
            dst.set_band_description(1, "elevation")
            dst.update_tags(**all_tags)


def write_hillshade_png(dem: xr.DataArray, path: PathLike, *, max_size: int = 2048) -> None:
    """Grey hillshade preview PNG (downsampled to at most ``max_size`` pixels a side).

    The shading is :func:`orokit.reports.dem_summary.hillshade` (cell sizes in metres,
    light from the north-west); NaN cells are black.
    """
    from affine import Affine
    from PIL import Image

    from orokit.io.atomic import atomic_path
    from orokit.reports.dem_summary import hillshade

    step = max(int(math.ceil(max(dem.shape) / max_size)), 1)
    small = dem
    if step > 1:
        small = dem.isel(y=slice(None, None, step), x=slice(None, None, step))
        small = small.rio.write_transform(dem.rio.transform() @ Affine.scale(step))
    hs = np.nan_to_num(hillshade(small), nan=0.0)
    img = Image.fromarray((hs * 255).astype(np.uint8), mode="L")
    with atomic_path(path) as tmp:
        img.save(tmp, format="PNG")


def write_tin_ply(tin: TIN, path: PathLike) -> None:
    """Write a TIN as an ASCII PLY mesh (vertices x y z, triangular faces)."""
    from orokit.io.atomic import atomic_open

    with atomic_open(path, "w") as fh:
        fh.write("ply\nformat ascii 1.0\ncomment orokit TIN\n")
        fh.write(f"element vertex {tin.xy.shape[0]}\nproperty double x\nproperty double y\nproperty double z\n")
        fh.write(f"element face {tin.n_triangles}\nproperty list uchar int vertex_indices\nend_header\n")
        np.savetxt(fh, np.column_stack([tin.xy, tin.z]), fmt="%.3f")
        np.savetxt(fh, np.column_stack([np.full(tin.n_triangles, 3), tin.triangles]), fmt="%d")
