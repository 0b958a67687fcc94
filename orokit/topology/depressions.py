"""Depressions (pits): the orometry of the negated elevation.

A depression is a peak of ``-h``: its depth is the prominence of ``-h`` (spill
elevation minus pit elevation), its spill (pour) point is the key saddle of ``-h``,
and the same engine, tie rules (earlier cell in raster order counts as deeper among
equal elevations) and edge flags apply. This module holds the pure pieces: the grid
the engine runs on (optional sea), the renaming of a peak table of ``-h`` into a
depressions table, and the area below the spill level.
"""
from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from orokit.topology import _kernels

__all__ = ["DEPRESSION_COLUMNS", "RENAME", "engine_grid", "depressions_table", "spill_areas"]

#: peak-table column of ``-h`` -> depressions-table column (elevations are negated back)
RENAME = {
    "prominence": "depth",
    "saddle_row": "spill_row", "saddle_col": "spill_col", "saddle_x": "spill_x", "saddle_y": "spill_y",
    "saddle_elevation": "spill_elevation",
    "island_parent": "deepest_parent", "island_parent_row": "deepest_parent_row",
    "island_parent_col": "deepest_parent_col",
    "line_parent": "spills_into", "line_parent_row": "spills_into_row", "line_parent_col": "spills_into_col",
    "prominence_parent": "depth_parent", "prominence_parent_row": "depth_parent_row",
    "prominence_parent_col": "depth_parent_col",
    "prominence_exact": "depth_exact",
}

#: Columns of the depressions table (index ``pit_id``), metres:
#: pit cell and elevation; ``depth`` = spill_elevation - elevation (NaN for the deepest
#: pit of a domain, which has no spill point); ``spill_*`` the pour point;
#: ``spills_into`` the first deeper pit met going down from the spill point (staying as
#: low as possible, the line parent of ``-h``); ``deepest_parent`` the deepest pit on the
#: other side at the spill level; ``depth_parent`` the first deeper-by-depth pit on that
#: way; ``area_m2`` the area of the cells strictly below the spill elevation connected
#: to the pit (its lake when filled to the brim); ``depth_exact`` False when terrain outside the data
#: could lower the spill point.
DEPRESSION_COLUMNS = [
    "row", "col", "x", "y", "lon", "lat", "elevation", "depth",
    "spill_row", "spill_col", "spill_x", "spill_y", "spill_elevation",
    "spills_into", "spills_into_row", "spills_into_col",
    "deepest_parent", "deepest_parent_row", "deepest_parent_col",
    "depth_parent", "depth_parent_row", "depth_parent_col",
    "area_m2", "depth_exact",
]


def engine_grid(z: Any, *, outside: str = "unknown", sea_level_m: float | None = None) -> tuple[Any, float | None, int]:
    """The grid whose peaks are the depressions of ``z`` (numpy or dask, NaN = nodata).

    Returns ``(g, sea, pad)``: ``g = -z``; cells at or below ``sea_level_m`` become the
    sea, one value ``sea`` lower than all land (so in ``g`` they are the highest); with
    ``outside="sea"`` a one-cell ring of sea surrounds the raster (``pad`` = 1), so every
    depression that would spill over the edge spills into the sea.
    """
    if outside not in ("unknown", "sea"):
        raise ValueError(f"outside must be 'unknown' or 'sea', got {outside!r}")
    sea = None
    if outside == "sea" or sea_level_m is not None:
        low = float(np.nanmin(z))
        if sea_level_m is not None:
            low = min(low, float(sea_level_m))
        sea = low - max(1.0, abs(low) * 1e-3)
        if sea_level_m is not None:
            z = np.where(z <= sea_level_m, sea, z)
    g = -z
    pad = 0
    if outside == "sea":
        assert sea is not None  # set above for outside == "sea"
        g = np.pad(g, 1, constant_values=-sea)
        pad = 1
    return g, sea, pad


def spill_areas(g: np.ndarray, peak_row: np.ndarray, peak_col: np.ndarray, row_area_m2: np.ndarray) -> np.ndarray:
    """Area (m²) of the cells strictly below the spill elevation connected to each pit
    (peaks of ``g`` at row/col); NaN for a pit that never spills (the deepest of its
    domain)."""
    g = np.ascontiguousarray(g, dtype=np.float64)
    flat = g.ravel()
    valid = ~np.isnan(flat)
    order = np.argsort(-np.where(valid, flat, -np.inf), kind="stable")
    out = _kernels.superlevel_death_areas(g, order, int(valid.sum()), np.asarray(row_area_m2, np.float64))
    return out[np.asarray(peak_row) * g.shape[1] + np.asarray(peak_col)]


def depressions_table(neg_peaks: pd.DataFrame, *, area_m2: np.ndarray | None = None, sea: float | None = None,
                      pad: int = 0) -> pd.DataFrame:
    """Depressions table from the peaks table of the engine grid (:func:`engine_grid`).

    Elevations are negated back, columns renamed (:data:`RENAME`), cells shifted by
    ``pad``; pits of the sea (elevation ``sea``) are dropped and references to them
    become -1 ("spills into the sea").
    """
    t = pd.DataFrame(neg_peaks.drop(columns="geometry", errors="ignore")).copy()
    t["elevation"] = -t["elevation"]
    t["saddle_elevation"] = -t["saddle_elevation"]
    root = t["island_parent"].to_numpy() < 0
    t.loc[root, "prominence"] = np.nan
    t = t.rename(columns=RENAME)
    t["area_m2"] = np.nan if area_m2 is None else np.asarray(area_m2, float)
    n = len(t)
    new_id = np.arange(n)
    if sea is not None:
        land = t["elevation"].to_numpy() != sea
        new_id = np.full(n, -1, np.int64)
        new_id[land] = np.arange(int(land.sum()))
        t = t[land]
        for ref in ("spills_into", "deepest_parent", "depth_parent"):
            ids = t[ref].to_numpy()
            mapped = np.where(ids >= 0, new_id[np.maximum(ids, 0)], -1)
            t[ref] = mapped
            t.loc[mapped < 0, [f"{ref}_row", f"{ref}_col"]] = -1
    if pad:
        for c in ("row", "col", "spill_row", "spill_col", "spills_into_row", "spills_into_col",
                  "deepest_parent_row", "deepest_parent_col", "depth_parent_row", "depth_parent_col"):
            v = t[c].to_numpy()
            t[c] = np.where(v >= 0, v - pad, -1)
    t = t.reset_index(drop=True)[DEPRESSION_COLUMNS]
    t.index.name = "pit_id"
    return t
