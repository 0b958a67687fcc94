"""Shared inputs of the terrain generators: the tree's arrays, its rivers, the output grid.

Every backend is a pure function ``render(tree, rivers, grid, rng, params) -> DataArray``
fed from the same sparse structure: a :class:`~orokit.topology.divide_tree.DivideTree`,
the rivers of :func:`tree_rivers` (the dual of its ridges, as in the ``argudo`` renderer)
and a north-up :class:`~orokit.raster.rasterize.Grid`.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import xarray as xr

from orokit.errors import DivideTreeError, InputError
from orokit.geodesy import metric_crs
from orokit.raster.rasterize import Grid
from orokit.raster.rivers import RiverNetwork, ridge_segments, river_network

__all__ = [
    "TreeArrays", "tree_arrays", "tree_rivers", "tree_sha256", "as_dataarray", "check_crs",
    "params_to_dict", "parse_params", "ridge_gradient", "ridge_cones",
]


@dataclass(frozen=True)
class TreeArrays:
    """A Divide Tree as arrays: peaks (n, 3), the saddles used by ridges (m, 3) and the
    ridges (m, 3) ``peak_a, peak_b, saddle`` (saddles renumbered 0..m-1)."""

    peaks: np.ndarray
    saddles: np.ndarray
    edges: np.ndarray


def tree_arrays(tree) -> TreeArrays:
    """Validated arrays of ``tree``.

    Raises
    ------
    DivideTreeError : no peak, non-finite coordinates or elevations, or a malformed tree.
    """
    if tree is None or tree.n_peaks == 0:
        raise DivideTreeError("the Divide Tree has no peaks; nothing to render (check the tree file)")
    tree.validate()
    p = tree.peaks[["x", "y", "elevation"]].to_numpy(float)
    s = tree.saddles[["x", "y", "elevation"]].to_numpy(float).reshape(-1, 3)
    e = tree.edges[["peak_a", "peak_b", "saddle"]].to_numpy(np.int64).reshape(-1, 3)
    used = np.unique(e[:, 2])
    if not np.isfinite(p).all() or (used.size and not np.isfinite(s[used]).all()):
        raise DivideTreeError("the Divide Tree has non-finite peak or saddle coordinates/elevations; fix or drop them")
    remap = np.full(max(s.shape[0], 1), -1, np.int64)
    remap[used] = np.arange(used.size)
    e = e.copy()
    if e.size:
        e[:, 2] = remap[e[:, 2]]
    return TreeArrays(p, s[used].reshape(-1, 3), e)


def check_crs(tree) -> Any:
    """The tree's pyproj CRS (None for a local frame); refuses a CRS whose coordinates are not metres
    (:func:`orokit.geodesy.metric_crs`)."""
    return metric_crs(tree.crs, "the Divide Tree")


def tree_sha256(tree) -> str:
    """Content hash of a tree (peak, saddle and ridge arrays), recorded in raster tags."""
    h = hashlib.sha256()
    for frame in (tree.peaks[["x", "y", "elevation"]], tree.saddles[["x", "y", "elevation"]]):
        h.update(np.ascontiguousarray(frame.to_numpy(np.float64)).tobytes())
    h.update(np.ascontiguousarray(tree.edges[["peak_a", "peak_b", "saddle"]].to_numpy(np.int64)).tobytes())
    return h.hexdigest()


def tree_rivers(tree, grid: Grid, *, margin_m: float = 5.0, slope: float = 0.01, cap=None) -> RiverNetwork:
    """The rivers of a tree on ``grid``'s extent: dual Voronoi edges of the straight ridges.

    :func:`orokit.raster.rivers.river_network` on the peaks and saddles with the
    unrefined (straight, no jitter) ridge pieces, so it is deterministic: every backend
    of one ranking run gets the same rivers. Outlets are on the grid border; beds lie
    ``margin_m`` below the ridges they face and fall ``slope`` m/m downstream, down to
    ``min(peak, saddle elevations) - margin_m``. ``cap`` (e.g. :func:`ridge_cones`) keeps every
    bed ``margin_m`` below it too (same nodes and receivers: the cap only moves the beds).
    """
    a = tree_arrays(tree)
    nodes = np.concatenate([a.peaks, a.saddles])
    ridges = ridge_segments(a.peaks, a.saddles, a.edges)
    base = float(nodes[:, 2].min()) - margin_m
    return river_network(ridges, nodes[:, :2], grid.extent, base_elevation=base, margin_m=margin_m, slope=slope,
                         cap=cap)


def ridge_gradient(tree) -> float:
    """The tree's ridge gradient (m/m): the summed drops from each peak to the saddles of its
    ridges over their summed horizontal lengths (0 for a tree without ridges)."""
    a = tree_arrays(tree)
    if not a.edges.size:
        return 0.0
    pk = np.concatenate([a.edges[:, 0], a.edges[:, 1]])
    sd = np.concatenate([a.edges[:, 2], a.edges[:, 2]])
    length = float(np.hypot(*(a.peaks[pk, :2] - a.saddles[sd, :2]).T).sum())
    return float((a.peaks[pk, 2] - a.saddles[sd, 2]).sum()) / length if length > 0 else 0.0


def ridge_cones(tree, slope: float, *, spacing_m: float, k_neighbours: int = 32):
    """The ground the ridges' flanks leave: a callable ``(k, 2) xy -> (k,)`` giving
    ``max_r (z_r - slope |xy - r|)`` over the ``k_neighbours`` ridge samples ``r`` nearest to each
    point (ridges linear from peak to saddle, sampled every ``spacing_m``; ``slope`` in m/m).
    A cap for :func:`tree_rivers`: beds stay ``margin_m`` below it."""
    from scipy.spatial import cKDTree

    a = tree_arrays(tree)
    if not a.edges.size:
        raise InputError("the Divide Tree has no ridge: no ridge cones")
    pk = np.concatenate([a.edges[:, 0], a.edges[:, 1]])
    sd = np.concatenate([a.edges[:, 2], a.edges[:, 2]])
    p0, p1 = a.peaks[pk, :2], a.saddles[sd, :2]
    n = np.maximum(np.ceil(np.hypot(*(p1 - p0).T) / spacing_m).astype(np.int64), 1) + 1
    seg = np.repeat(np.arange(p0.shape[0]), n)
    t = (np.arange(seg.size) - np.repeat(np.cumsum(n) - n, n)) / np.repeat(n - 1, n)
    rxy = p0[seg] + t[:, None] * (p1[seg] - p0[seg])
    rz = a.peaks[pk, 2][seg] + t * (a.saddles[sd, 2][seg] - a.peaks[pk, 2][seg])
    k = min(int(k_neighbours), rz.size)
    kd = cKDTree(rxy)

    def cap(xy: np.ndarray) -> np.ndarray:
        d, i = kd.query(np.asarray(xy, float).reshape(-1, 2), k=k, workers=-1)
        d, i = d.reshape(-1, k), i.reshape(-1, k)
        return (rz[i] - float(slope) * d).max(axis=1)

    return cap


def as_dataarray(z: np.ndarray, grid: Grid, crs: Any, attrs: dict[str, Any] | None = None) -> xr.DataArray:
    """``z`` (ny, nx) as a float32 elevation DataArray on ``grid`` with CRS and transform."""
    import rioxarray  # noqa: F401 - registers the .rio accessor
    from affine import Affine

    if z.shape != (grid.ny, grid.nx):
        raise ValueError(f"array shape {z.shape} does not match the grid ({grid.ny}, {grid.nx})")
    x, y = grid.centres()
    da = xr.DataArray(np.asarray(z, dtype=np.float32), dims=("y", "x"), coords={"y": y, "x": x}, name="elevation")
    if crs is not None:
        da = da.rio.write_crs(crs)
    da = da.rio.write_transform(Affine(grid.cell_size_m, 0.0, grid.x0, 0.0, -grid.cell_size_m, grid.y0))
    da.attrs.update({"units": "m", "local_grid": crs is None, "cell_size_m": (grid.cell_size_m, grid.cell_size_m)})
    da.attrs.update(attrs or {})
    return da


def spread(h0: np.ndarray, src: np.ndarray, grid: Grid, slope: float) -> np.ndarray:
    """``min over source cells (h0 + slope x 8-connected path length)`` on ``grid`` (Dijkstra on the
    8-connected grid, diagonal steps sqrt 2 cells long)."""
    from orokit.generators._rusnell_kernels import cost_field

    gi, gj = np.nonzero(src)
    w = np.full((grid.ny, grid.nx, 4), slope * grid.cell_size_m)
    w[:, :, 1] *= math.sqrt(2.0)
    w[:, :, 3] *= math.sqrt(2.0)
    stamp = np.full((grid.ny, grid.nx), -1, np.int32)
    fixed = np.full((grid.ny, grid.nx), -1, np.int32)
    cost = np.zeros((grid.ny, grid.nx))
    srcc = np.zeros((grid.ny, grid.nx))
    touched = np.empty(grid.ny * grid.nx, np.int64)
    cost_field(w, gi.astype(np.int64), gj.astype(np.int64), h0[gi, gj], np.inf, np.ones(2), False,
               np.zeros((0, 0)), 0.0, stamp, 0, cost, srcc, touched, fixed, np.zeros((0, 0), np.uint8))
    return cost


def exemplar_slope(exemplar: xr.DataArray, *, quantile: float | None = None) -> float:
    """Mean slope of a real DEM as a gradient (m/m): ``tan`` of its mean slope angle (or, with
    ``quantile`` in [0, 1], of that quantile of its slope angles).

    Central differences with the grid's metric cell sizes (per row on lon/lat grids), NaN
    cells left out; the same slope as :func:`orokit.validate.landform.landform_statistics`.

    Raises
    ------
    InputError : the DEM has no two valid neighbouring cells.
    """
    from orokit.raster.shade import row_cell_sizes_m

    z = np.asarray(exemplar.values, dtype=np.float64)
    if z.ndim != 2 or min(z.shape) < 3:
        raise InputError(f"the exemplar DEM must be a 2-D grid of at least 3 x 3 cells; got shape {z.shape}")
    dxr, dy = row_cell_sizes_m(exemplar)
    gy, gx = np.gradient(z)
    g = np.hypot(gx / np.asarray(dxr, dtype=np.float64)[:, None], gy / float(dy))
    g = g[np.isfinite(g)]
    if g.size == 0:
        raise InputError("the exemplar DEM has no valid slope (all nodata?); pass a DEM with valid cells")
    a = np.arctan(g)
    return float(np.tan(np.mean(a) if quantile is None else np.quantile(a, quantile)))


# ----------------------------------------------------------------------------- parameters
def params_to_dict(params: Any) -> dict[str, Any]:
    """A parameters dataclass as a JSON-ready dict (tuples become lists)."""
    return {f.name: (list(v) if isinstance(v := getattr(params, f.name), tuple) else v)
            for f in dataclasses.fields(params)}


def _convert(name: str, text: str, default: Any, choices: tuple[str, ...] | None) -> Any:
    if isinstance(default, bool):
        low = text.strip().lower()
        if low in ("1", "true", "yes", "on"):
            return True
        if low in ("0", "false", "no", "off"):
            return False
        raise InputError(f"parameter {name}={text!r} is not a boolean; write {name}=true or {name}=false")
    if isinstance(default, int):
        try:
            return int(text)
        except ValueError:
            raise InputError(f"parameter {name}={text!r} is not an integer") from None
    if isinstance(default, float):
        try:
            v = float(text)
        except ValueError:
            raise InputError(f"parameter {name}={text!r} is not a number") from None
        if not math.isfinite(v):
            raise InputError(f"parameter {name}={text!r} must be finite")
        return v
    if isinstance(default, tuple):
        try:
            items = json.loads(text) if text.strip().startswith("[") else text.split(",")
            return tuple(type(default[0])(v) if default else float(v) for v in items)
        except (ValueError, TypeError):
            raise InputError(f"parameter {name}={text!r} is not a comma-separated list") from None
    if choices and text not in choices:
        raise InputError(f"parameter {name}={text!r} is not one of {', '.join(choices)}")
    return text


def parse_params(cls: type, pairs: list[str] | tuple[str, ...] | dict[str, Any] = ()) -> Any:
    """An instance of the parameters dataclass ``cls`` from ``K=V`` strings (or a dict).

    Unknown keys and values of the wrong type raise :class:`InputError` listing the valid
    keys; range checks are the dataclass's own (``__post_init__``).

    Examples
    --------
    >>> from orokit.generators.belhadj import BelhadjParams
    >>> parse_params(BelhadjParams, ["hurst=0.8"]).hurst
    0.8
    """
    fields = {f.name: f for f in dataclasses.fields(cls)}
    defaults = cls()
    values: dict[str, Any] = {}
    items = pairs.items() if isinstance(pairs, dict) else []
    if not isinstance(pairs, dict):
        parsed = []
        for pair in pairs:
            if "=" not in pair:
                raise InputError(f"--param {pair!r} is not KEY=VALUE (e.g. hurst=0.8)")
            k, v = pair.split("=", 1)
            parsed.append((k.strip(), v.strip()))
        items = parsed
    for k, v in items:
        if k not in fields:
            raise InputError(f"unknown parameter {k!r} for {cls.__name__}; valid keys: {', '.join(fields)}")
        choices = fields[k].metadata.get("choices") if fields[k].metadata else None
        values[k] = _convert(k, v, getattr(defaults, k), choices) if isinstance(v, str) else v
    return cls(**values)
