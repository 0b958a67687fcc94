"""Figures of the generator backends (Belhadj 2007 Figs. 3/5/6) and the ranking table's hillshades."""
from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["plot_belhadj_stage", "shade"]


def shade(z: np.ndarray, cell_size_m: float) -> np.ndarray:
    """Grey hillshade in [0, 1] of an elevation array (light from the north-west)."""
    import xarray as xr
    from affine import Affine

    from orokit.reports.dem_summary import hillshade

    da = xr.DataArray(np.asarray(z, dtype=np.float32), dims=("y", "x"))
    da = da.rio.write_transform(Affine(cell_size_m, 0.0, 0.0, 0.0, -cell_size_m, 0.0))
    return np.nan_to_num(hillshade(da), nan=0.0)


def plot_belhadj_stage(ax: Any, z: np.ndarray, state: np.ndarray, *, cell_size_m: float, kind: str,
                       title: str = "") -> Any:
    """One panel of the Belhadj figures.

    kind : ``skeleton`` (ridge/river cells coloured by elevation on white), ``mdi`` (the
        paper's Fig. 5: cells known after MDI in black, still NULL in white, skeleton in red) or
        ``terrain`` (hillshade with the skeleton cells drawn faintly, Figs. 3 and 6).
    """
    from matplotlib.colors import ListedColormap

    known = state == 1
    if kind == "skeleton":
        ax.imshow(np.where(known, z, np.nan), cmap="terrain", interpolation="nearest")
    elif kind == "mdi":
        img = np.zeros(state.shape, np.uint8)  # 0 white (NULL)
        img[state == 2] = 1  # black: filled by MDI
        img[known] = 2  # red: skeleton
        ax.imshow(img, cmap=ListedColormap(["white", "black", "red"]), vmin=0, vmax=2, interpolation="nearest")
    elif kind == "terrain":
        ax.imshow(shade(z, cell_size_m), cmap="gray", vmin=0, vmax=1, interpolation="nearest")
    else:
        raise ValueError(f"kind must be skeleton, mdi or terrain, got {kind!r}")
    ax.set_title(title, fontsize=9)
    ax.set_xticks([])
    ax.set_yticks([])
    return ax
