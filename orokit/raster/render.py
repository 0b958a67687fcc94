"""Terrain from a Divide Tree (Argudo et al. 2019, §6): skeleton, raster, noise, erosion, orometry.

:func:`render_elevation` turns a :class:`~orokit.topology.divide_tree.DivideTree` into a
georeferenced elevation raster whose peaks, saddles and ridges are those of the tree.
The stages live in :mod:`orokit.raster.skeleton` (rivers, samples, TIN) and
:mod:`orokit.raster.enforce` (orometry enforcement); the writers in :mod:`orokit.io.raster_io`.
"""
from __future__ import annotations

import json
import logging
import sys
import time
import warnings
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

import numpy as np
from scipy import ndimage

from orokit import __version__
from orokit._typing import SeedLike
from orokit.errors import DivideTreeError, InputError, OrokitWarning
from orokit.geodesy import metric_crs
from orokit.raster import _kernels
from orokit.raster.enforce import enforce_orometry
from orokit.raster.erosion import erode_multiscale
from orokit.raster.hillslope import limit_slope
from orokit.raster.interpolate import field_elevation, valley_width
from orokit.raster.noise import falloff, fractal_noise, lowpass, power_law_fit, power_law_noise, spectral_noise
from orokit.raster.params import RenderParams
from orokit.raster.profiles import hillslope_profile
from orokit.raster.rasterize import MAX_CELLS, as_extent, burn_max, make_grid, rasterize_tin, set_cells
from orokit.raster.refine import densify
from orokit.raster.skeleton import build_skeleton, tree_extent

logger = logging.getLogger(__name__)

__all__ = ["render_elevation", "resolve_seed"]


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
        entropy = np.random.SeedSequence().entropy
        assert isinstance(entropy, int)  # a fresh SeedSequence draws one int
        return entropy
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


def _load_xarray() -> None:
    """Import rioxarray (the .rio accessor) with xarray and dask.array (which xarray imports with the
    first DataArray): ~0.6 CPU s that only the render's result needs."""
    import rioxarray  # noqa: F401


def _preload_xarray() -> Future | None:
    """:func:`_load_xarray` on a second thread while the render runs (None: already imported). The
    skeleton's and the kernels' stretches without the GIL leave the thread room; the render
    imports nothing of xarray's or dask's while it runs, and joins before building its result."""
    if "rioxarray" in sys.modules:
        return None
    pool = ThreadPoolExecutor(1, thread_name_prefix="orokit-imports")
    try:
        return pool.submit(_load_xarray)
    finally:
        pool.shutdown(wait=False)


def _node_distance(mask: np.ndarray, res: float) -> np.ndarray:
    """float32 Euclidean distance (metres) of every cell to the nearest cell where ``mask`` is False: the
    values of ``distance_transform_edt(mask, sampling=res).astype(np.float32)`` (same feature cells,
    same float64 arithmetic; :func:`_kernels.feature_distance`)."""
    ft = np.zeros((2,) + mask.shape, np.int32)
    ndimage.distance_transform_edt(mask, sampling=res, return_distances=False, return_indices=True, indices=ft)
    return _kernels.feature_distance(ft, float(res))


def _slope_weight(z: np.ndarray, res: float, smooth_m: float, power: float) -> np.ndarray:
    """``(s / mean s) ** power`` of the slope ``s`` of ``z`` smoothed over ``smooth_m`` (RMS 1 when power=1)."""
    if power == 0:
        return np.ones(z.shape, np.float32)
    # the weight is smooth at smooth_m: computed on a grid ~4 cells per smooth_m, then interpolated
    f = max(int(smooth_m / (4.0 * res)), 1)
    zc = z[::f, ::f].astype(np.float32)
    zs = ndimage.gaussian_filter(zc, max(0.5 * smooth_m / (res * f), 0.5))
    gy, gx = np.gradient(zs, res * f)
    s = np.hypot(gx, gy) ** np.float32(power)
    if f > 1:
        s = ndimage.zoom(s, (z.shape[0] / s.shape[0], z.shape[1] / s.shape[1]), order=1, grid_mode=True,
                         mode="nearest")[: z.shape[0], : z.shape[1]]
        if s.shape != z.shape:
            s = np.pad(s, [(0, z.shape[0] - s.shape[0]), (0, z.shape[1] - s.shape[1])], mode="edge")
    m = float(np.sqrt(np.mean(s * s, dtype=np.float64)))
    return (s / np.float32(m)).astype(np.float32) if m > 0 else np.ones(z.shape, np.float32)


def _detail_weights(z: np.ndarray, res: float, near: np.ndarray, smooth_m: float, power: float,
                    flat_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """Where the sub-lambda detail acts and how strongly, from one gradient of the skeleton raster ``z``.

    ``act``: ``1 - near`` (the fade near peaks and saddles) times 0 where the slope (central
    differences; the least of the cell's and its 8 neighbours') is below ``flat_deg``, rising linearly
    to 1 at twice that slope, so lake, fjord and valley floors and their edge cells stay flat (no
    flat test when ``flat_deg`` is 0). ``weight``: ``act`` times the slope smoothed over ``smooth_m``
    (Gaussian sigma ``smooth_m / 2``) to ``power``, normalised to an RMS of 1 (1 when ``power`` is 0).
    """
    return _detail_act(near, *_detail_slope(z, res, smooth_m, power, flat_deg))


def _gaussian_weights(sigma: float, truncate: float = 4.0) -> np.ndarray:
    """The 1-D weights :func:`scipy.ndimage.gaussian_filter` correlates with (radius
    ``int(truncate sigma + 0.5)``, the same float64 values and order)."""
    lw = int(truncate * float(sigma) + 0.5)
    x = np.arange(-lw, lw + 1)
    phi = np.exp(-0.5 / (float(sigma) * float(sigma)) * x ** 2)
    return np.ascontiguousarray((phi / phi.sum())[::-1])


def _detail_slope(z: np.ndarray, res: float, smooth_m: float, power: float,
                  flat_deg: float) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The parts of :func:`_detail_weights` that need the slope of ``z`` only: the flat test (None
    when ``flat_deg`` is 0) and the normalised smoothed slope (None when ``power`` is 0)."""
    z32 = np.ascontiguousarray(z, np.float32)
    if min(z32.shape) < 2:
        np.gradient(z32)  # numpy's error: too small for a gradient
    # numba kernels with numpy's and scipy's float32 operations: the same bytes, one pass each on all cores
    s = _kernels.slope_magnitude(z32, np.float32(res))
    flat = None
    if flat_deg > 0:
        flat = _kernels.flat_ramp(s, np.float32(np.tan(np.radians(flat_deg))))
    if power == 0:
        return flat, None
    w = _kernels.gaussian_nearest(s, _gaussian_weights(max(0.5 * smooth_m / res, 0.5)))
    if power != 1:
        w **= np.float32(power)
    m = float(np.sqrt(np.mean(w * w, dtype=np.float64)))
    return flat, (w * np.float32(1.0 / m) if m > 0 else np.ones(z.shape, np.float32))


def _detail_act(near: np.ndarray, flat: np.ndarray | None, w: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """``(act, weight)`` of :func:`_detail_weights` from the fade ``near`` and :func:`_detail_slope`'s parts."""
    act = 1.0 - near
    if flat is not None:
        act *= flat
    if w is None:
        return act, act.copy()
    return act, (w * act).astype(np.float32, copy=False)


def _replacing_noise(law: Future, shape: tuple[int, int], res: float, params: RenderParams,
                     rng: np.random.Generator) -> np.ndarray | None:
    """The replacing detail's noise (:func:`power_law_noise`) for the law ``(c, beta)`` that ``law`` holds;
    None when no law was fitted (``c`` 0)."""
    c, beta = law.result()
    if c <= 0:
        return None
    return power_law_noise(shape, res, c=c * params.detail_gain ** 2, beta=beta, largest_m=params.detail_largest_m,
                           steepen=params.detail_steepen, steepen_below_m=params.detail_fit_m[0],
                           min_beta=params.detail_min_beta, sharp=True, rng=rng)


def _median_relief(z: np.ndarray, res: float, window_m: float = 1000.0) -> float:
    """Median of ``max - min`` over non-overlapping ``window_m`` blocks of ``z`` (whole grid if smaller)."""
    f = max(int(round(window_m / res)), 1)
    ny, nx = (z.shape[0] // f) * f, (z.shape[1] // f) * f
    if ny == 0 or nx == 0:
        return float(np.ptp(z))
    b = z[:ny, :nx].reshape(ny // f, f, nx // f, f)
    return float(np.median(b.max(axis=(1, 3)) - b.min(axis=(1, 3))))


def _field(grid, rxy: np.ndarray, rz: np.ndarray, rivers, params: RenderParams) -> np.ndarray:
    """The ``surface="field"`` raster: nearest ridge and river cells by distance transforms."""
    vxy, vz, va = densify(rivers, 0.5 * grid.cell_size_m)
    rr, rc, rok = grid.cell_of(rxy)
    vr, vc, vok = grid.cell_of(vxy)
    if not rok.any() or not vok.any():
        raise InputError("no ridge or no river of the Divide Tree crosses the extent; use surface='tin'")
    return field_elevation((grid.ny, grid.nx), grid.cell_size_m, (rr[rok], rc[rok]), rz[rok], (vr[vok], vc[vok]),
                           vz[vok], valley_width(va[vok], coef=params.valley_coef),
                           profile=hillslope_profile if params.profiles == "learned" else None,
                           smooth_m=params.field_smooth_m,
                           beyond_depth_m=params.min_prominence_m)


def render_elevation(
    tree,
    *,
    cell_size_m: float,
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
    tree : DivideTree in a projected CRS or a local metric frame (x, y, elevation in metres).
    cell_size_m : cell size of the output in metres.
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
    CRSError : the tree's coordinates are not metres (a geographic CRS, or a projected one in feet).
    DivideTreeError : empty or malformed tree.

    Notes
    -----
    1. Skeleton (:func:`build_skeleton`): dual rivers, refinement, Poisson samples, TIN.
    2. Barycentric rasterization of the TIN at cell centres; ridge pieces are burnt in
       (cells raised to the ridge elevation), then peak and saddle cells are set to
       their exact elevation so the raster's highest paths follow the ridges.
    3. Sub-lambda detail (``detail_gain``, on): the skeleton's wavelengths below lambda (facets) are
       replaced by its own power law continued there, weighted by its slope, none on flat floors nor
       near peaks and saddles; texture (twins); the paper's multi-fractal noise of amplitude
       ``noise_ratio * eps`` (off by default), masked by ``1 - g(d / R)`` around peaks and saddles
       (g = (1 - r^2)^3).
    4. Erosion (optional): fastscapelib stream power at 100, 50, 30 m with
       compensating uplift ``U = g(d / R)``.
    5. Peak and saddle cells are reset to their exact elevations; the raster's orometry
       is made the tree's (:func:`orokit.raster.enforce.enforce_orometry`).
    """
    params = params or RenderParams()
    seed = resolve_seed(rng)
    rng = np.random.default_rng(seed)
    crs = metric_crs(tree.crs, "the Divide Tree")
    xarray_job = _preload_xarray()
    if tree.n_peaks == 0:
        raise DivideTreeError("the Divide Tree has no peaks; nothing to render")
    ext = as_extent(extent) if extent is not None else tree_extent(tree)
    grid = make_grid(ext, cell_size_m, max_cells=max_cells)  # errors before any allocation
    pxy = tree.peaks[["x", "y"]].to_numpy(float)
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

    # the distance to the nodes (a distance transform that releases the GIL) runs on a second thread from
    # the moment the skeleton has placed the nodes: while the TIN is built and rasterized (one core busy),
    # then the power law is fitted and, with the replacing detail, the slope weights and the low-pass of
    # the skeleton run; dist_job.result() is the same array wherever it is first needed
    dist_jobs: list[Future] = []

    def nodes_placed(node_xyz: np.ndarray) -> None:
        mask = np.ones((grid.ny, grid.nx), bool)
        row, col, ok = grid.cell_of(node_xyz[:, :2])
        mask[row[ok], col[ok]] = False
        pool = ThreadPoolExecutor(1, thread_name_prefix="orokit-distance")
        dist_jobs.append(pool.submit(_node_distance, mask, grid.cell_size_m))
        pool.shutdown(wait=False)  # its thread ends with the job

    skel = build_skeleton(tree, extent=ext, params=params, saddle_clearance_m=1.5 * grid.cell_size_m, rng=rng,
                          on_nodes=nodes_placed)
    if not dist_jobs:
        nodes_placed(skel.node_xyz)
    dist_job = dist_jobs.pop()
    timings = dict(skel.timings)

    t0 = time.perf_counter()
    rxy, rz, _, rorig = densify(skel.ridges, 0.5 * grid.cell_size_m, origin=True)
    if params.surface == "field" and skel.rivers.segments.size:
        z = _field(grid, rxy, rz, skel.rivers, params)
        if params.field_weight < 1.0:
            tin = rasterize_tin(skel.tin, grid)
            z = np.where(np.isnan(tin), z, params.field_weight * z + (1.0 - params.field_weight) * tin)
    else:
        z = rasterize_tin(skel.tin, grid)
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
    if params.max_slope_deg is not None:
        z = limit_slope(z, grid.cell_size_m, params.max_slope_deg)
    timings["raster"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    pool = ThreadPoolExecutor(1, thread_name_prefix="orokit-noise")
    detail = {}
    # the detail draws from its own stream: turning it on leaves the texture and noise of the render as they were
    detail_rng = np.random.default_rng([seed, 1])
    c, beta = 0.0, 3.0
    # the skeleton's own power law is fitted where the TIN resolves the tree's relief (none on a grid
    # narrower than the fit band: its few wavenumbers there give no law)
    fits = min(grid.ny, grid.nx) * grid.cell_size_m >= params.detail_fit_m[1]
    law_job: Future | None = None
    detail_noise: Future | None = None
    if params.detail_replace and params.detail_gain > 0 and fits:
        # the replacing detail's law and noise on a second thread: the law is fitted there (it only reads
        # z, and is joined before z changes), then its noise drawn and shaped (numpy's draws and the FFTs
        # release the GIL) while the weights and the low-pass run here; the same draws from detail_rng,
        # the same bytes
        law_job = pool.submit(power_law_fit, z, grid.cell_size_m, fit_m=params.detail_fit_m)
        detail_noise = pool.submit(_replacing_noise, law_job, z.shape, grid.cell_size_m, params, detail_rng)
    elif params.detail_gain > 0:
        c, beta = power_law_fit(z, grid.cell_size_m, fit_m=params.detail_fit_m) if fits else (0.0, 3.0)
        detail = {"detail_beta": round(beta, 3), "detail_log10_c": round(float(np.log10(c)), 3) if c > 0 else None}
    pool.shutdown(wait=False)
    noise_amp = params.noise_ratio * params.min_prominence_m
    # the compensating uplift is only used by the erosion and the multi-fractal noise
    uplift = falloff(dist_job.result() / np.float32(params.uplift_radius)) if erosion or noise_amp > 0 else None
    if params.smooth_m > 0:
        if law_job is not None:
            law_job.result()  # the law is fitted before the smoothing
        # round the TIN's planar facets and creases below the meshing scale; peaks and saddles kept
        keep = falloff(dist_job.result() / np.float32(max(params.texture_clearance_m, grid.cell_size_m)))
        zs = ndimage.gaussian_filter(z, params.smooth_m / grid.cell_size_m, mode="nearest")
        z += (zs - z) * (1.0 - keep)
        del zs, keep
    if law_job is not None and detail_noise is not None:
        # the TIN carries nothing below its meshing distance but facets: its wavelengths below
        # detail_largest_m are replaced by the power law continued there (peaks and saddles kept)
        flat, w = _detail_slope(z, grid.cell_size_m, params.detail_largest_m, params.detail_slope_power,
                                params.detail_flat_deg)
        low = lowpass(z, grid.cell_size_m, params.detail_largest_m)
        c, beta = law_job.result()  # fitted: z may change
        detail = {"detail_beta": round(beta, 3), "detail_log10_c": round(float(np.log10(c)), 3) if c > 0 else None}
        if c > 0:
            act, weight = _detail_act(
                falloff(dist_job.result() / np.float32(max(params.texture_clearance_m, grid.cell_size_m))), flat, w)
            del flat, w
            z += (low - z) * act
            del low
            d = detail_noise.result() * weight
            detail["detail_rms_m"] = round(float(d.std()), 3)
            z += d
            del act, weight, d
        else:
            del flat, w, low
    elif params.detail_gain > 0 and c > 0:
        # sub-lambda relief: the power law continued below detail_largest_m, minus what the
        # (smoothed) skeleton has there already, where the skeleton is steep, away from peaks and saddles
        fade, weight = _detail_weights(z, grid.cell_size_m,
                                       falloff(dist_job.result()
                                               / np.float32(max(params.texture_clearance_m, grid.cell_size_m))),
                                       params.detail_largest_m, params.detail_slope_power, params.detail_flat_deg)
        d = power_law_noise(z.shape, grid.cell_size_m, c=c * params.detail_gain ** 2, beta=beta,
                            largest_m=params.detail_largest_m, minus=z, steepen=params.detail_steepen,
                            steepen_below_m=params.detail_fit_m[0], min_beta=params.detail_min_beta,
                            rng=detail_rng) * weight
        detail["detail_rms_m"] = round(float(d.std()), 3)
        z += d
        del fade, weight, d
    texture_rms = params.texture_rms_m
    if texture_rms == 0 and params.texture_relief_ratio > 0:
        # no measured texture (a real tree): real DEMs have texture RMS ~ 0.07-0.12 x their median 1 km relief
        texture_rms = params.texture_relief_ratio * _median_relief(z, grid.cell_size_m)
    if texture_rms * params.texture_gain > 0:
        # texture where the skeleton is steep (real valley floors and glaciers are smooth),
        # faded near peaks and saddles; mean amplitude = gain x the type's texture RMS
        fade = 1.0 - falloff(dist_job.result() / np.float32(max(params.texture_clearance_m, grid.cell_size_m)))
        weight = _slope_weight(z, grid.cell_size_m, params.texture_largest_m, params.texture_slope_power) * fade
        z += spectral_noise(z.shape, grid.cell_size_m, rms=params.texture_gain * texture_rms,
                            beta=params.texture_beta, largest_m=params.texture_largest_m, rng=rng) * weight
        del fade, weight
    dist_job.result()  # raises what the distance transform raised
    del dist_job
    if noise_amp > 0:
        assert uplift is not None
        zmin, zmax = float(z.min()), float(z.max())
        rough = (z - zmin) / max(zmax - zmin, 1e-6)
        z += fractal_noise(z.shape, grid.cell_size_m, amplitude=noise_amp, roughness=rough, rng=rng) * (1.0 - uplift)
        del rough
    # the detail, texture and noise never cut the tree's ridges below their profile (a cut ridge
    # lowers its saddle's pass: the peak behind it gains prominence)
    burn_max(z, grid, rxy, rz)
    timings["noise"] = time.perf_counter() - t0

    if erosion:
        assert uplift is not None
        t0 = time.perf_counter()
        z = erode_multiscale(z, grid.cell_size_m, uplift, scales_m=params.erosion_scales,
                             steps=params.erosion_steps, k_dt=params.erosion_k_dt,
                             max_nodes=params.erosion_max_nodes)
        timings["erosion"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    set_cells(z, grid, nodes[:, :2], nodes[:, 2])
    enforce_orometry(z, grid, skel, label=label, trench_slope=params.trench_slope,
                     trench_depth_m=params.trench_depth_ratio * params.min_prominence_m,
                     keep_hills_m=params.keep_hill_ratio * params.min_prominence_m, cut_slope=params.cut_slope,
                     cut_depth_m=params.cut_depth_ratio * params.min_prominence_m)
    timings["orometry"] = time.perf_counter() - t0

    if xarray_job is not None:
        xarray_job.result()
    import rioxarray  # noqa: F401 - registers the .rio accessor
    import xarray as xr

    x, y = grid.centres()
    da = xr.DataArray(z.astype(np.float32, copy=False), dims=("y", "x"), coords={"y": y, "x": x}, name="elevation")
    from affine import Affine

    if crs is not None:
        da = da.rio.write_crs(crs)
    da = da.rio.write_transform(Affine(grid.cell_size_m, 0.0, grid.x0, 0.0, -grid.cell_size_m, grid.y0))
    da.attrs.update({
        "units": "m",
        "generator": "orokit.raster.render_elevation (Argudo et al. 2019, section 6)",
        "orokit_version": __version__,
        "parameters": json.dumps({**params.to_dict(), "cell_size_m": grid.cell_size_m, "extent": list(ext),
                                  "erosion": bool(erosion), "texture_rms_used_m": round(float(texture_rms), 3), **detail}),
        "seed": seed,
        "local_grid": crs is None,
        "cell_size_m": (grid.cell_size_m, grid.cell_size_m),
        "n_tree_peaks": int(tree.n_peaks),
        "timings": json.dumps({k: round(v, 3) for k, v in timings.items()}),
    })
    logger.info("rendered %d x %d at %g m in %.2f s", grid.nx, grid.ny, grid.cell_size_m, sum(timings.values()))
    return (da, skel) if return_skeleton else da
