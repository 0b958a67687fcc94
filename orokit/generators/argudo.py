"""Argudo et al. 2019 backend: today's orokit renderer (:func:`orokit.raster.render.render_elevation`).

A thin wrapper, not a fork: the TIN of ridges, dual rivers and Poisson samples, noise,
constrained erosion and orometry enforcement all come from :mod:`orokit.raster`.
It builds its own rivers on the refined (jittered) ridges, so the shared ``rivers``
argument is not used (they are the same construction on unrefined ridges).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import xarray as xr

from orokit.errors import InputError
from orokit.raster.rasterize import Grid
from orokit.raster.rivers import RiverNetwork

__all__ = ["ArgudoParams", "render"]


@dataclass(frozen=True)
class ArgudoParams:
    """Parameters of the Argudo backend: the renderer's defaults plus ``erosion``.

    lam : meshing distance lambda (m); min_prominence_m : eps (m), noise stays below it;
    erosion : run the multi-scale constrained erosion (fastscapelib); the other
    parameters of :class:`orokit.raster.render.RenderParams` keep their defaults.
    """

    lam: float = 200.0
    min_prominence_m: float = 30.0
    noise_ratio: float = 0.3
    erosion: bool = True

    def __post_init__(self) -> None:
        if not (self.lam > 0 and np.isfinite(self.lam)):
            raise InputError(f"lam must be a positive number of metres, got {self.lam!r}")
        if not (self.min_prominence_m >= 0 and np.isfinite(self.min_prominence_m)):
            raise InputError(f"min_prominence_m must be >= 0 metres, got {self.min_prominence_m!r}")
        if not (0.0 <= self.noise_ratio < 0.5):
            raise InputError(f"noise_ratio must be in [0, 0.5) (noise below eps / 2), got {self.noise_ratio!r}")


def render(tree, rivers: RiverNetwork | None, grid: Grid, rng: np.random.Generator,
           params: ArgudoParams | None = None) -> xr.DataArray:
    """Elevation raster of a Divide Tree after Argudo et al. 2019, §6 (see
    :func:`orokit.raster.render.render_elevation`); ``rivers`` is not used."""
    from orokit.raster import render as _render
    from orokit.raster.params import RenderParams

    params = params or ArgudoParams()
    kw = {f.name: getattr(params, f.name) for f in dataclasses.fields(params) if f.name != "erosion"}
    rp = RenderParams(**kw)
    da = _render.render_elevation(tree, cell_size_m=grid.cell_size_m, extent=grid.extent, erosion=params.erosion,
                                  params=rp, rng=rng)
    return da
