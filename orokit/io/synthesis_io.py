"""Write a synthesized Divide Tree: GeoPackage layers, reference TXT, peaks table, metadata."""
from __future__ import annotations

import json
import logging
import math
from pathlib import Path

import pandas as pd

from orokit._typing import PathLike
from orokit.io.atomic import atomic_path, staged_folder, write_text_atomic
from orokit.io.divide_tree_gpkg import write_divide_tree_gpkg
from orokit.io.divide_tree_txt import write_divide_tree_txt
from orokit.topology.divide_tree import DivideTree
from orokit.topology.tables import validate_peak_table

logger = logging.getLogger(__name__)

__all__ = ["SYNTHESIS_FILES", "write_synthesis"]

SYNTHESIS_FILES = ("dividetree.gpkg", "dividetree.txt", "peaks.csv", "synthesis.json")


def write_synthesis(tree: DivideTree, outdir: PathLike, *, peaks: pd.DataFrame, txt_cell_m: float = 30.0,
                    extra: dict | None = None) -> Path:
    """Write ``tree`` and its peaks table ``peaks`` into ``outdir`` (locked; staged beside it and moved in when complete).

    Files: ``dividetree.gpkg`` (layers peaks, with the orometry columns of ``peaks``,
    saddles, ridges), ``dividetree.txt`` (reference TXT format, elevations in feet, pixel
    coordinates on a virtual grid of ``txt_cell_m`` cells with the origin at the domain's
    north-west corner), ``peaks.csv`` (``peaks``: the columns of ``orokit analyze``, from
    :func:`orokit.synthesis.peaks_table`), ``synthesis.json`` (attrs).
    """
    validate_peak_table(peaks)
    with staged_folder(outdir, marker="synthesis.json", names=SYNTHESIS_FILES) as stage:
        _write(tree, stage, peaks=peaks, txt_cell_m=txt_cell_m, extra=extra)
    logger.info("wrote %s", outdir)
    return Path(outdir)


def _write(tree: DivideTree, out: Path, *, peaks: pd.DataFrame, txt_cell_m: float, extra: dict | None) -> None:
    write_divide_tree_gpkg(tree, out / "dividetree.gpkg", peaks=peaks)
    dom = tree.attrs.get("domain") or {}
    x0 = float(dom.get("x0", tree.peaks["x"].min()))
    top = float(dom.get("y0", tree.peaks["y"].min())) + float(dom.get("height", tree.peaks["y"].max() - tree.peaks["y"].min()))
    height = max(1, math.ceil(float(dom.get("height", 1.0)) / txt_cell_m))
    local_peaks = tree.peaks[["x", "y", "elevation"]].copy()
    local_peaks["x"] -= x0
    local_peaks["y"] -= top
    local_saddles = tree.saddles[["x", "y", "elevation"]].copy()
    local_saddles["x"] -= x0
    local_saddles["y"] -= top
    local = DivideTree(local_peaks, local_saddles, tree.edges[["peak_a", "peak_b", "saddle"]], None, {})
    write_divide_tree_txt(local, out / "dividetree.txt", height=height, cell_size_m=txt_cell_m)
    with atomic_path(out / "peaks.csv") as tmp:
        pd.DataFrame(peaks.drop(columns="geometry")).to_csv(tmp, float_format="%.10g")
    meta = dict(tree.attrs)
    meta["crs"] = None if tree.crs is None else tree.crs.to_wkt()
    meta["n_peaks"] = tree.n_peaks
    meta["txt_cell_m"] = txt_cell_m
    meta.update(extra or {})
    write_text_atomic(out / "synthesis.json", json.dumps(meta, indent=2, default=str))
