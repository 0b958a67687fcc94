"""Round-trip report: synthetic twins of real DEMs, re-analysed and classified (paper §7.1, Fig. 17).

Each region folder is the output of ``orokit synthesize --like REGION`` followed by
``orokit validate --model``: ``synthesis.json``, ``dem.tif`` and ``validation.json``.
:func:`roundtrip_rows` gathers one table row per region, next to the accuracy of the
region's real disks from the classification report; :func:`write_twin_png` draws the
real DEM and its synthetic twin side by side.
"""
from __future__ import annotations

import io
import json
import logging
import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from orokit._typing import PathLike

logger = logging.getLogger(__name__)

__all__ = ["landform_table", "render_landform_markdown", "roundtrip_rows", "render_roundtrip_markdown",
           "write_landform_png", "write_twin_png", "real_dem_of"]

#: the six floored statistics of issue 11, in table order
SIX = ("slope_deg", "curvature_per_km", "relief_1km", "spectral_slope", "flat_share", "hypsometry")

#: per-region accuracy of the paper's synthetic terrains (Argudo et al. 2019, §7.1)
PAPER_SYNTHETIC_ACCURACY = {"sahara": 100, "appalachians": 100, "karakoram": 100, "himalaya": 99, "norway": 89}


def _read_json(path: Path) -> dict[str, Any]:
    return json.loads(path.read_text(encoding="utf-8"))


def real_dem_of(folder: PathLike):
    """The real DEM a twin folder was synthesized ``--like`` (a manifest dataset), or None."""
    folder = Path(folder)
    meta = _read_json(folder / "synthesis.json") if (folder / "synthesis.json").is_file() else {}
    like = meta.get("like") or folder.name
    if Path(str(like)).is_file():
        from orokit.io.dem import read_dem

        return read_dem(str(like), z_units="m")
    from orokit.data import open_dataset_dem
    from orokit.errors import DataError

    try:
        return open_dataset_dem(str(like))
    except DataError:
        logger.warning("no real DEM found for %s (like=%r)", folder, like)
        return None


def roundtrip_rows(folders: list[PathLike], *, real_accuracy: pd.DataFrame | None = None) -> pd.DataFrame:
    """One row per twin folder: recovered / extra peaks, histogram errors, classification.

    ``real_accuracy`` is the classification report's per-class table
    (``tables/per_class_<R>km.csv``: ``region``, ``random_accuracy_%``, ``spatial_accuracy_%``).
    """
    rows = []
    real = real_accuracy.set_index("region") if real_accuracy is not None and len(real_accuracy) else None
    for d in map(Path, folders):
        v = _read_json(d / "validation.json")
        s = v["summary"]
        meta = _read_json(d / "synthesis.json") if (d / "synthesis.json").is_file() else {}
        name = d.name
        emd = [float(val) for k, val in s.items() if k.startswith("emd_")]
        t = meta.get("render_timings_s") or {}
        row = {
            "region": name,
            "shape": s.get("shape"),
            "cell_m": round(float(s.get("cell_size_m", float("nan"))), 1),
            "tree_peaks": s.get("tree_peaks"),
            "recovered_%": 100.0 * float(s.get("recovered_share", float("nan"))),
            "extra_%": 100.0 * float(s.get("extra_share", float("nan"))),
            "median_prom_error_m": s.get("median_abs_prominence_error_m"),
            "max_bin_error": s.get("max_bin_error"),
            "max_emd_elevation_m": s.get("emd_elevation"),
            "max_emd_prominence_m": s.get("emd_prominence"),
            "mean_emd_all": float(np.mean(emd)) if emd else float("nan"),
            "disks": s.get("n_disks", 0),
            "synthetic_disk_acc_%": 100.0 * float(s["disk_accuracy"]) if "disk_accuracy" in s else float("nan"),
            "vote": s.get("predicted") or "-",
            "vote_correct": bool(s.get("vote_correct", False)),
            "in_model": name in ((v.get("classification") or {}).get("probabilities") or {}),
            "render_s": round(float(sum(t.values())), 2) if t else float("nan"),
        }
        if real is not None and name in real.index:
            row["real_disk_acc_%"] = float(real.loc[name, "random_accuracy_%"])
            if "spatial_accuracy_%" in real.columns:
                row["real_disk_acc_spatial_%"] = float(real.loc[name, "spatial_accuracy_%"])
        else:
            row["real_disk_acc_%"] = float("nan")
            row["real_disk_acc_spatial_%"] = float("nan")
        rows.append(row)
    return pd.DataFrame(rows)


def _fmt(v: Any, nd: int = 1) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (float, np.floating)):
        return f"{v:.{nd}f}"
    return str(v)


def _n_ge(a: pd.Series, b: pd.Series) -> int:
    ok = a.notna() & b.notna()
    return int((a[ok] >= b[ok]).sum())


def render_roundtrip_markdown(table: pd.DataFrame, *, header: str = "", model: str = "",
                              landforms: dict[str, pd.DataFrame] | None = None) -> str:
    """Markdown page: the round-trip table, totals, the landform tables (region ->
    :func:`landform_table`) and the twin figures."""
    cols = [("region", 0), ("shape", 0), ("tree_peaks", 0), ("recovered_%", 1), ("extra_%", 1),
            ("max_bin_error", 3), ("max_emd_prominence_m", 1), ("disks", 0), ("synthetic_disk_acc_%", 0),
            ("real_disk_acc_%", 0), ("real_disk_acc_spatial_%", 0), ("vote", 0)]
    names = {"tree_peaks": "tree peaks >= eps", "recovered_%": "recovered %", "extra_%": "extra %",
             "max_bin_error": "max bin error", "max_emd_prominence_m": "EMD prominence (m)",
             "disks": "disks", "synthetic_disk_acc_%": "synthetic disks right %",
             "real_disk_acc_%": "real disks right % (random split)",
             "real_disk_acc_spatial_%": "real disks right % (spatial)", "vote": "overall vote"}
    lines = ["# Round trip: synthetic twins of the real DEMs", ""]
    if header:
        lines += [header, ""]
    lines += ["| " + " | ".join(names.get(c, c) for c, _ in cols) + " |",
              "|" + "|".join("---" if c in ("region", "shape", "vote") else "---:" for c, _ in cols) + "|"]
    for _, r in table.iterrows():
        cells = []
        for c, nd in cols:
            v = r.get(c)
            txt = _fmt(v, nd)
            if c == "vote" and txt != "-":
                if not bool(r.get("in_model", True)):
                    txt = f"{txt} (region not in the model)"
                elif not bool(r.get("vote_correct")):
                    txt = f"{txt} (wrong)"
            cells.append(txt)
        lines.append("| " + " | ".join(cells) + " |")
    lines.append("")
    if len(table):
        rec = table["recovered_%"].astype(float)
        ext = table["extra_%"].astype(float)
        syn = table["synthetic_disk_acc_%"].astype(float)
        real = table["real_disk_acc_%"].astype(float)
        inm = table["in_model"].astype(bool) if "in_model" in table else pd.Series(True, index=table.index)
        syn = syn.where(inm)
        both = syn.notna() & real.notna()
        spatial = table.get("real_disk_acc_spatial_%", pd.Series(np.nan, index=table.index)).astype(float)
        lines += [
            "## Totals",
            "",
            f"- Peaks recovered: mean {rec.mean():.1f} % (min {rec.min():.1f} %, {int((rec >= 95).sum())} of "
            f"{len(rec)} regions >= 95 %); extra peaks: mean {ext.mean():.1f} % (max {ext.max():.1f} %, "
            f"{int((ext <= 5).sum())} of {len(ext)} regions <= 5 %).",
            f"- Reclassification ({int(inm.sum())} twins of regions the model knows): overall vote right for "
            f"{int(table['vote_correct'][inm].sum())} of {int(inm.sum())}; "
            f"synthetic disks right {syn.mean():.1f} % on average"
            + (f"; synthetic >= real accuracy for {int((syn[both] >= real[both]).sum())} of {int(both.sum())} regions"
               f" with the random split, >= the spatial hold-out accuracy for {_n_ge(syn, spatial)} of "
               f"{int((syn.notna() & spatial.notna()).sum())}" if both.any() else "") + ".",
            "- A twin is an unseen terrain: its disks share nothing with the training disks, so the spatial "
            "hold-out column (validation strip away from every training disk) is the fairer yardstick; the "
            "random split lets overlapping neighbours of a validation disk into the training set.",
            "- Paper (Argudo et al. 2019, §7.1, R = 30 km, 15 regions): synthetic Sahara, Appalachians, Karakoram "
            "100 %, Himalaya 99 %, Norway 89 %.",
            "",
        ]
    if model:
        lines += [f"Model: `{model}`.", ""]
    if landforms:
        labels = [c for c in next(iter(landforms.values())).columns if c not in ("halves", "floor", "target")
                  and not c.endswith(" met")]
        lines += ["## Landforms: real DEM, render of its real Divide Tree and free twin (issue 11)", "",
                  "Distances between each synthetic DEM and the real one at the same cell size "
                  "(`orokit.validate.landform`), beside the same distance between the real DEM's north and south "
                  "halves; target = max(2 x halves, floor). The render of the real tree is `orokit render "
                  "dividetree.gpkg --like REGION --seed 0` of the region's own analysis (defaults).", ""]
        totals = {lab: sum(int(t.loc[list(SIX), f"{lab} met"].all()) for t in landforms.values()) for lab in labels}
        lines += ["Regions with all six floored statistics within target: "
                  + "; ".join(f"{lab} {n} of {len(landforms)}" for lab, n in totals.items()) + ".", ""]
        for name, t in landforms.items():
            lines += render_landform_markdown(name, t, labels)
    figs = [r["region"] for _, r in table.iterrows()]
    if figs:
        lines += ["## Real DEM and synthetic twin (paper Fig. 17)", ""]
        for name in figs:
            lines += [f"![{name}]({name}/twin.png)", ""]
    return "\n".join(lines)


def write_twin_png(real, synthetic, path: PathLike, *, title: str = "", dpi: int = 80, colors: int = 96) -> Path:
    """Hillshades of a real DEM and its synthetic twin side by side (small palette PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from orokit.io.atomic import write_bytes_atomic
    from orokit.reports.dem_summary import _small_png, plot_hillshade

    panels = [(real, "real"), (synthetic, "synthetic twin")] if real is not None else [(synthetic, "synthetic twin")]
    fig, axes = plt.subplots(1, len(panels), figsize=(4.6 * len(panels), 3.9), constrained_layout=True, squeeze=False)
    try:
        for ax, (dem, label) in zip(axes[0], panels):
            plot_hillshade(ax, dem, max_pixels=400, title=f"{title} - {label}" if title else label)
        buf = io.BytesIO()
        fig.savefig(buf, dpi=dpi, format="png", metadata={"Software": None})
    finally:
        plt.close(fig)
    return write_bytes_atomic(Path(path), _small_png(buf.getvalue(), colors))


def landform_table(real, synthetic: dict) -> pd.DataFrame:
    """Landform distances of every synthetic DEM (label -> DataArray) to the real DEM.

    One row per statistic (:data:`orokit.validate.landform.DISTANCES`): the real north/south
    halves' distance, the target ``max(2 x halves, floor)``, and per synthetic DEM its
    distance and whether it meets the target (``<label>`` and ``<label> met`` columns).
    """
    from orokit.validate.landform import compare_landforms, landform_statistics, split_halves

    rs = landform_statistics(real)
    halves = tuple(landform_statistics(h) for h in split_halves(real))
    out = None
    for label, dem in synthetic.items():
        c = compare_landforms(rs, landform_statistics(dem), halves=halves)  # type: ignore[arg-type]
        if out is None:
            out = c[["halves", "floor", "target"]].copy()
        out[label] = c["distance"]
        out[f"{label} met"] = c["ok"]
    return out if out is not None else pd.DataFrame()


def render_landform_markdown(name: str, table: pd.DataFrame, labels: list[str]) -> list[str]:
    """Markdown lines of one region's landform table and its figure."""
    from orokit.validate.landform import DISTANCES

    lines = [f"### {name}", "", "| statistic | real halves | target | " + " | ".join(labels) + " |",
             "|---|---:|---:|" + "---:|" * len(labels)]
    for stat, r in table.iterrows():
        cells = [f"{_fmt(float(r[lab]), 3)}{'' if bool(r[f'{lab} met']) else ' (over)'}" for lab in labels]
        floor = "" if not math.isfinite(float(r["floor"])) else f", floor {float(r['floor']):g}"
        label = DISTANCES.get(str(stat), str(stat)).replace("|", "\\|")  # a pipe would split the cell
        lines.append(f"| {label}{' *' if stat in SIX else ''} | "
                     f"{_fmt(float(r['halves']), 3)} | {_fmt(float(r['target']), 3)}{floor} | " + " | ".join(cells) + " |")
    met = [f"{lab}: {int(table.loc[list(SIX), f'{lab} met'].sum())} of 6" for lab in labels]
    lines += ["", f"Six floored statistics (*) within target: {'; '.join(met)}.", "",
              f"![{name} landforms]({name}/landforms.png)", ""]
    return lines


def write_landform_png(dems: dict, path: PathLike, *, title: str = "") -> Path:
    """The landform figure (:func:`orokit.reports.landform.plot_landforms`) as a 150 dpi PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from orokit.io.atomic import write_bytes_atomic
    from orokit.reports.landform import plot_landforms

    fig = plot_landforms(dems, title=title)
    try:
        buf = io.BytesIO()
        fig.savefig(buf, dpi=150, format="png", metadata={"Software": None})
    finally:
        plt.close(fig)
    return write_bytes_atomic(Path(path), buf.getvalue())
