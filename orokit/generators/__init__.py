"""Terrain generators: one backend per paper, all fed from the same Divide Tree and rivers.

Each backend module holds a frozen dataclass of its paper's default parameters and a
pure ``render(tree, rivers, grid, rng, params) -> DataArray``. :data:`GENERATORS` lists
them with their inputs; :func:`render_terrain` resolves the seed, builds the shared
rivers and records generator, parameters, seed, version and input hash in the attrs
(which :func:`orokit.io.raster_io.write_cog` writes as tags).

=========  ============================================  ========================
name       paper                                         status
=========  ============================================  ========================
argudo     Argudo et al. 2019 (orokit's renderer)        complete
belhadj    Belhadj 2007 (skeleton, MDI, MD)              tree or particle skeleton
rusnell    Rusnell 2009 (least-cost fields, blending)    no pareidolia mode
guerin     Guérin 2016 (sparse construction tree)        amplification (tree or DEM)
michel     Michel 2015 (plates, warped fBm, watershed)   peak positions or vector map
=========  ============================================  ========================
"""
from __future__ import annotations

import importlib
import json
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from orokit.errors import InputError

if TYPE_CHECKING:
    import xarray as xr

__all__ = ["GeneratorSpec", "GENERATORS", "get_generator", "render_terrain", "describe_generators"]


@dataclass(frozen=True)
class GeneratorSpec:
    """A registered backend: its module (``render`` + params class), paper and inputs."""

    name: str
    paper: str
    module: str
    params_class: str
    inputs: tuple[str, ...]
    status: str

    def load(self) -> tuple[Any, type]:
        """The backend's ``render`` function and parameters class."""
        mod = importlib.import_module(self.module)
        return mod.render, getattr(mod, self.params_class)

    def params(self, values: list[str] | tuple[str, ...] | dict[str, Any] = ()) -> Any:
        """Parameters from ``K=V`` strings or a dict over the defaults."""
        from orokit.generators.base import parse_params

        return parse_params(self.load()[1], values)


GENERATORS: dict[str, GeneratorSpec] = {
    "argudo": GeneratorSpec("argudo", "Argudo et al. 2019, doi:10.1145/3355089.3356535",
                            "orokit.generators.argudo", "ArgudoParams", ("tree",), "complete"),
    "belhadj": GeneratorSpec("belhadj", "Belhadj 2007, doi:10.1145/1294685.1294717",
                             "orokit.generators.belhadj", "BelhadjParams", ("tree", "rivers"),
                             "skeleton = the tree's ridges and the rivers, or the paper's particles (skeleton=particles); "
                             "MDI then MD"),
    "rusnell": GeneratorSpec("rusnell", "Rusnell et al. 2009, doi:10.1007/s00371-009-0350-5",
                             "orokit.generators.rusnell", "RusnellParams", ("tree", "exemplar", "rivers"),
                             "Algorithm 1 with profile fit (exemplar) or w_s = 1, secondary ridges, halting at "
                             "water (rivers), generators=FILE; no pareidolia mode"),
    "guerin": GeneratorSpec("guerin", "Guérin et al. 2016, doi:10.1111/cgf.12821",
                            "orokit.generators.guerin", "GuerinParams", ("tree", "rivers", "exemplar"),
                            "amplification (§5.3) of the tree's interpolated ridges and rivers, or of a coarse DEM "
                            "(coarse=DEM), with a complete, constrained or K-SVD dictionary of exemplar patches"),
    "michel": GeneratorSpec("michel", "Michel et al. 2015, doi:10.2312/egsh.20151011",
                            "orokit.generators.michel", "MichelParams", ("tree", "rivers", "exemplar"),
                            "peak positions + rivers, or the paper's vector map (map=FILE); orokit's defaults for T1, "
                            "T2, blur, k, slopes; valley sides at the exemplar's mean slope (optional exemplar)"),
}


def get_generator(name: str) -> GeneratorSpec:
    """The registered generator ``name``; unknown names list the valid ones."""
    try:
        return GENERATORS[name]
    except KeyError:
        raise InputError(f"unknown generator {name!r}; choose one of {', '.join(GENERATORS)}") from None


def describe_generators() -> str:
    """A text listing of every generator, its inputs, status and default parameters."""
    from orokit.generators.base import params_to_dict

    lines = []
    for spec in GENERATORS.values():
        _, cls = spec.load()
        lines.append(f"{spec.name}: {spec.paper}")
        lines.append(f"  inputs: {', '.join(spec.inputs)}; status: {spec.status}")
        for k, v in params_to_dict(cls()).items():
            lines.append(f"  --param {k}={json.dumps(v) if not isinstance(v, str) else v}")
    return "\n".join(lines)


def render_terrain(
    tree,
    *,
    generator: str = "argudo",
    cell_size_m: float | None = None,
    extent: tuple[float, float, float, float] | None = None,
    grid=None,
    params: Any = None,
    rivers=None,
    exemplar: xr.DataArray | None = None,
    seed: int | None = None,
    inputs: dict[str, Any] | None = None,
) -> xr.DataArray:
    """Elevation raster of a Divide Tree with the backend ``generator``.

    Parameters
    ----------
    tree : DivideTree in a projected CRS or a local metric frame.
    generator : a name of :data:`GENERATORS`.
    cell_size_m, extent : output grid (default extent: the tree's domain), or ``grid``.
    params : the backend's parameters dataclass, a dict or ``K=V`` strings (default: its paper's).
    rivers : a :class:`~orokit.raster.rivers.RiverNetwork` shared between backends
        (default :func:`orokit.generators.base.tree_rivers` on the grid).
    exemplar : a real DEM (metres) for generators whose inputs include ``exemplar`` (each
        backend says when it needs one).
    inputs : data of file-valued parameters (``metadata={"file": ...}`` fields, e.g. Guérin's
        ``coarse``), already read by the caller, or ``learned``: what a backend with an
        exemplar learns from it (its module's ``learn(exemplar, grid, params, rng)``: Guérin's
        dictionary, Rusnell's profile), to render several trees without learning again;
        passed to the backend by name.
    seed : int seed; None draws fresh entropy. The int is recorded in ``attrs['seed']``
        and the same seed gives the same raster.

    Returns
    -------
    DataArray (float32 metres, NaN nodata, CRS/transform) with attrs ``generator``,
    ``parameters`` (JSON), ``seed``, ``orokit_version``, ``tree_sha256``, ``timings`` (JSON), and
    ``derived`` (JSON) when the backend set parameter values from its inputs.
    """
    from orokit import __version__
    from orokit.generators.base import params_to_dict, tree_arrays, tree_rivers, tree_sha256
    from orokit.raster.rasterize import as_extent, make_grid
    from orokit.raster.render import resolve_seed
    from orokit.raster.skeleton import tree_extent

    spec = get_generator(generator)
    render, cls = spec.load()
    if params is None:
        params = cls()
    elif not isinstance(params, cls):
        params = spec.params(params)
    tree_arrays(tree)  # empty or malformed trees fail here, with the same message for every backend
    if grid is None:
        if cell_size_m is None:
            raise InputError("render_terrain needs cell_size_m (or a grid)")
        ext = as_extent(extent) if extent is not None else tree_extent(tree)
        grid = make_grid(ext, cell_size_m)
    seed = resolve_seed(seed)
    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    if rivers is None and "rivers" in spec.inputs:
        rivers = tree_rivers(tree, grid)
    t_rivers = time.perf_counter() - t0
    extra = {"exemplar": exemplar} if "exemplar" in spec.inputs else {}
    extra.update(inputs or {})
    da = render(tree, rivers, grid, rng, params, **extra)
    timings = da.attrs.get("timings", {})
    timings = json.loads(timings) if isinstance(timings, str) else dict(timings)
    if "rivers" in spec.inputs:
        timings["rivers"] = t_rivers
    counts = da.attrs.pop("cell_counts", None)
    derived = da.attrs.pop("derived", None)
    da.attrs.update({
        "units": "m",
        "generator": spec.name,
        "generator_paper": spec.paper,
        "parameters": json.dumps({**params_to_dict(params), "cell_size_m": grid.cell_size_m, "extent": list(grid.extent)}),
        "seed": seed,
        "orokit_version": __version__,
        "tree_sha256": tree_sha256(tree),
        "n_tree_peaks": int(tree.n_peaks),
        "timings": json.dumps({k: round(float(v), 3) for k, v in timings.items()}),
    })
    if counts is not None:
        da.attrs["cell_counts"] = json.dumps(counts)
    if derived is not None:  # parameters a backend set from its inputs (e.g. the exemplar)
        da.attrs["derived"] = json.dumps(derived)
    return da
