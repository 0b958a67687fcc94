"""Report of the exact analyses of the manifest DEMs (reports/analysis/README.md).

Per dataset: size, peaks above the threshold, the share flagged exact, timings, a
comparison with the paper's reference Divide Tree (when the manifest has one), and
a figure of the Divide Tree over the hillshade (the paper's Fig. 6 style).
"""
from __future__ import annotations

import io
import logging
from pathlib import Path
from typing import Any

import numpy as np

from orokit._typing import PathLike
from orokit.io.atomic import write_bytes_atomic, write_text_atomic

logger = logging.getLogger(__name__)

__all__ = ["plot_divide_tree", "analysis_rows", "build_analysis_report"]


def plot_divide_tree(ax, dem, result, *, title: str | None = None):
    """Hillshade of ``dem`` with the Divide Tree of ``result`` (ridges, saddles, peaks by prominence)."""
    from matplotlib.collections import LineCollection

    from orokit.reports.dem_summary import plot_hillshade

    plot_hillshade(ax, dem, title=title)
    scale = 1.0 if (dem.rio.crs is not None and dem.rio.crs.is_geographic) else 1000.0
    ridges = result.tree.ridges()
    segs = [np.asarray(g.coords) / scale for g in ridges.geometry]
    ax.add_collection(LineCollection(segs, colors="crimson", linewidths=0.6, alpha=0.8))
    s = result.saddles
    ax.scatter(s["x"] / scale, s["y"] / scale, s=3, c="limegreen", marker="o", linewidths=0, label="saddles")
    p = result.peaks
    size = 2 + 30 * np.sqrt(np.clip(p["prominence"].to_numpy(float), 0, None) / max(float(p["prominence"].max()), 1.0))
    ax.scatter(p["x"] / scale, p["y"] / scale, s=size, c="orange", edgecolors="k", linewidths=0.2, label="peaks")
    ax.legend(loc="lower right", fontsize=7, framealpha=0.7)
    return ax


def analysis_rows(folders: list[PathLike], *, figures_dir: PathLike | None = None) -> list[dict[str, Any]]:
    """One row per analysis folder; writes a Divide Tree figure per dataset into ``figures_dir``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    import orokit
    from orokit.analysis import read_analysis
    from orokit.data import dataset_path, load_manifest, open_dataset_dem
    from orokit.io.dem import read_dem
    from orokit.io.divide_tree_io import read_divide_tree_txt
    from orokit.reports.dem_summary import _small_png
    from orokit.validate.reference import compare_with_reference

    manifest = load_manifest()
    rows = []
    for folder in folders:
        res = read_analysis(folder)
        name = res.attrs.get("dataset") or Path(folder).name
        known = name in manifest.names
        dem = open_dataset_dem(name) if known else read_dem(res.attrs["source"])
        p = res.peaks
        row: dict[str, Any] = {
            "dataset": name,
            "shape": "x".join(str(v) for v in res.attrs.get("shape", dem.shape)),
            "eps_m": res.attrs.get("min_prominence_m"),
            "peaks": len(p),
            "exact_prominence": float(p["prominence_exact"].mean()) if len(p) else float("nan"),
            "exact_isolation": float(p["isolation_exact"].mean()) if len(p) else float("nan"),
            "max_prominence_m": float(p["prominence"].max()) if len(p) else float("nan"),
            "seconds": sum(res.attrs.get("timings_s", {}).values()),
        }
        if known and manifest[name].files_with_role("divide_tree"):
            ref = read_divide_tree_txt(dataset_path(name, role="divide_tree"), height=dem.shape[0])
            all_peaks = orokit.analyze(dem, min_prominence_m=0.0, isolation=False).peaks
            row.update(compare_with_reference(all_peaks, ref, (dem.shape[0], dem.shape[1])))
        if figures_dir is not None:
            fig, ax = plt.subplots(figsize=(6.4, 5.2), dpi=100)
            plot_divide_tree(ax, dem, res, title=f"{name}: Divide Tree, prominence >= {row['eps_m']:g} m")
            buf = io.BytesIO()
            fig.savefig(buf, format="png", bbox_inches="tight")
            plt.close(fig)
            out = Path(figures_dir) / f"{name}.png"
            out.parent.mkdir(parents=True, exist_ok=True)
            write_bytes_atomic(out, _small_png(buf.getvalue(), 96))
            row["figure"] = f"figures/{name}.png"
        rows.append(row)
        logger.info("analysis report: %s", name)
    return rows


def build_analysis_report(folders: list[PathLike], output: PathLike) -> Path:
    """Write the Markdown report ``output`` (figures beside it in ``figures/``)."""
    out = Path(output)
    rows = analysis_rows(folders, figures_dir=out.parent / "figures")
    lines = [
        "# Exact analysis of the manifest DEMs",
        "",
        "Made by `make report` (`orokit analyze NAME` then `orokit analysis-report`). Peaks with prominence",
        "above the threshold; *exact* = share of peaks whose value cannot change with terrain beyond the",
        "data edge. Reference = the paper's Divide Tree for that DEM (`<name>.txt`, made with a modified",
        "version of Kirmse's program, not finalised, elevations off by 1-2 ft): *ref in ours* is the share",
        "of its peaks at or next to (<= 1 cell) one of orokit's peaks at eps = 0, *ours in ref* the share",
        "of orokit's exact peaks with prominence >= 102 ft at or next to a reference peak.",
        "",
        "Timings of the last run are in `timings.csv` beside this page (not committed: they change with",
        "the machine's load; `benchmarks/` records speed).",
        "",
        "| dataset | cells | peaks | exact prom. | exact isol. | max prom. (m) | ref. peaks | ref in ours | ours in ref |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['dataset']} | {r['shape']} | {r['peaks']} | {r['exact_prominence']:.0%} | "
            f"{r['exact_isolation']:.0%} | {r['max_prominence_m']:.0f} | "
            f"{r.get('reference_peaks', '')} | {_pct(r.get('ref_in_ours'))} | {_pct(r.get('ours_in_ref'))} |"
        )
    lines += ["", "## Divide Trees", ""]
    for r in rows:
        if "figure" in r:
            lines.append(f"![{r['dataset']}]({r['figure']})")
    lines.append("")
    timings = ["dataset,seconds"] + [f"{r['dataset']},{r['seconds']:.3f}" for r in rows]
    write_text_atomic(out.parent / "timings.csv", "\n".join(timings) + "\n")
    return write_text_atomic(out, "\n".join(lines))


def _pct(v) -> str:
    return "" if v is None or (isinstance(v, float) and np.isnan(v)) else f"{v:.1%}"
