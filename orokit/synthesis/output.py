"""Write a synthesized Divide Tree: GeoPackage layers, reference TXT, peaks table, metadata."""
from __future__ import annotations

import json
import logging
import math
from pathlib import Path

import pandas as pd

from orokit._typing import PathLike
from orokit.topology.divide_tree import DivideTree

logger = logging.getLogger(__name__)

__all__ = ["SYNTHESIS_FILES", "write_synthesis"]

SYNTHESIS_FILES = ("dividetree.gpkg", "dividetree.txt", "peaks.csv", "synthesis.json")


def write_synthesis(tree: DivideTree, outdir: PathLike, *, txt_cell_m: float = 30.0,
                    extra: dict | None = None) -> Path:
    """Write ``tree`` into ``outdir`` (locked; staged beside it and moved in when complete).

    Files: ``dividetree.gpkg`` (layers peaks, saddles, ridges), ``dividetree.txt``
    (reference TXT format, elevations in feet, pixel coordinates on a virtual grid of
    ``txt_cell_m`` cells with the origin at the domain's north-west corner),
    ``peaks.csv`` (the columns of ``orokit analyze``), ``synthesis.json`` (attrs).
    """
    from orokit.io.atomic import staged_folder

    with staged_folder(outdir, marker="synthesis.json", names=SYNTHESIS_FILES) as stage:
        _write(tree, stage, txt_cell_m=txt_cell_m, extra=extra)
    logger.info("wrote %s", outdir)
    return Path(outdir)


def _write(tree: DivideTree, out: Path, *, txt_cell_m: float, extra: dict | None) -> None:
    from orokit.io.atomic import atomic_path, write_text_atomic
    from orokit.io.divide_tree_io import write_divide_tree_gpkg, write_divide_tree_txt
    from orokit.synthesis.tree import peaks_table

    write_divide_tree_gpkg(tree, out / "dividetree.gpkg")
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
    write_divide_tree_txt(local, out / "dividetree.txt", height=height, cell_size=txt_cell_m)
    table = peaks_table(tree)
    with atomic_path(out / "peaks.csv") as tmp:
        pd.DataFrame(table.drop(columns="geometry")).to_csv(tmp, float_format="%.10g")
    meta = dict(tree.attrs)
    meta["crs"] = None if tree.crs is None else tree.crs.to_wkt()
    meta["n_peaks"] = tree.n_peaks
    meta["txt_cell_m"] = txt_cell_m
    meta.update(extra or {})
    write_text_atomic(out / "synthesis.json", json.dumps(meta, indent=2, default=str))
