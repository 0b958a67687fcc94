"""Landform figure: real DEM beside synthetic ones, and their slope and 1 km relief distributions.

One figure per region: hillshades tinted by elevation on one shared colour scale, axes in km
from the same (south-west) corner, north up, a scale bar; below, the slope and 1 km relief
histograms of every panel with labelled axes and units.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from orokit.raster.shade import hillshade

if TYPE_CHECKING:  # pragma: no cover
    import xarray as xr
    from matplotlib.figure import Figure

__all__ = ["plot_landforms"]

_COLOURS = ("black", "tab:orange", "tab:blue", "tab:green")


def _slope_relief(dem: xr.DataArray) -> tuple[np.ndarray, np.ndarray]:
    from orokit.validate.landform import slope_and_relief

    slope, rel = slope_and_relief(dem, window_m=1000.0)
    return slope[np.isfinite(slope)], rel[np.isfinite(rel)]


def _scale_bar(ax, width_km: float) -> None:
    step = 10 ** math.floor(math.log10(max(width_km / 4, 1e-3)))
    length = max(k * step for k in (1, 2, 5) if k * step <= width_km / 3)
    x0, y0 = 0.05 * width_km, 0.05 * width_km
    ax.plot([x0, x0 + length], [y0, y0], color="white", lw=4, solid_capstyle="butt")
    ax.plot([x0, x0 + length], [y0, y0], color="black", lw=2, solid_capstyle="butt")
    ax.text(x0 + length / 2, y0 + 0.02 * width_km, f"{length:g} km", ha="center", va="bottom", fontsize=8,
            color="black", bbox={"facecolor": "white", "alpha": 0.7, "lw": 0, "pad": 1})


def plot_landforms(dems: dict[str, xr.DataArray], *, title: str = "", max_pixels: int = 500) -> Figure:
    """Figure of DEMs (label -> DataArray on metric grids, real first) and their landforms.

    Row 1: hillshade tinted by elevation, one colour scale for all panels, km from each
    DEM's south-west corner, north up, scale bar. Row 2: slope distribution (degrees) and
    1 km relief distribution (m), share of cells, one line per DEM.
    """
    import matplotlib.pyplot as plt

    n = len(dems)
    fig = plt.figure(figsize=(4.2 * n, 7.6), dpi=150)
    gs = fig.add_gridspec(2, max(n, 2), height_ratios=[1.25, 1.0], wspace=0.4)
    zmin = min(float(np.nanmin(d.values)) for d in dems.values())
    zmax = max(float(np.nanmax(d.values)) for d in dems.values())
    im = None
    for k, (label, dem) in enumerate(dems.items()):
        ax = fig.add_subplot(gs[0, k])
        step = max(1, math.ceil(max(dem.shape) / max_pixels))
        shade = hillshade(dem)[::step, ::step]
        z = np.asarray(dem.values, dtype=np.float64)[::step, ::step]
        t = dem.rio.transform()
        ny, nx = dem.shape
        w_km, h_km = abs(t.a) * nx / 1000.0, abs(t.e) * ny / 1000.0
        ext = (0.0, w_km, 0.0, h_km)  # row 0 is north: imshow's default origin puts it on top
        ax.imshow(shade, cmap="gray", extent=ext, vmin=0, vmax=1, interpolation="nearest")
        im = ax.imshow(z, cmap="terrain", alpha=0.45, extent=ext, vmin=zmin, vmax=zmax, interpolation="nearest")
        _scale_bar(ax, w_km)
        ax.set_title(label, fontsize=10)
        ax.set_xlabel("km east of the south-west corner", fontsize=8)
        ax.set_ylabel("km north", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.annotate("N", xy=(0.93, 0.93), xytext=(0.93, 0.80), xycoords="axes fraction", ha="center",
                    arrowprops={"arrowstyle": "-|>", "color": "black"}, fontsize=9)
    if im is not None:
        cb = fig.colorbar(im, ax=fig.axes[:n], shrink=0.8, pad=0.01)
        cb.set_label("elevation (m)")
    ax_s = fig.add_subplot(gs[1, 0])
    ax_r = fig.add_subplot(gs[1, 1])
    stats = {label: _slope_relief(dem) for label, dem in dems.items()}
    rmax = max(float(np.quantile(r, 0.995)) for _, r in stats.values() if r.size) or 1.0
    for (label, (slope, rel)), colour in zip(stats.items(), _COLOURS):
        ax_s.hist(slope, bins=np.linspace(0, 90, 91).tolist(), weights=np.full(slope.size, 1 / max(slope.size, 1)),
                  histtype="step", color=colour, label=label, lw=1.4)
        ax_r.hist(rel, bins=np.linspace(0, rmax, 60).tolist(), weights=np.full(rel.size, 1 / max(rel.size, 1)),
                  histtype="step", color=colour, label=label, lw=1.4)
    ax_s.set_xlabel("slope (degrees, central differences)")
    ax_s.set_ylabel("share of cells per 1-degree bin")
    ax_r.set_xlabel("local relief in ~1 km windows (m)")
    ax_r.set_ylabel("share of cells per bin")
    ax_s.legend(fontsize=8)
    ax_r.legend(fontsize=8)
    if title:
        fig.suptitle(title)
    return fig
