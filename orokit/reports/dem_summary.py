"""Per-dataset DEM summary: statistics, a hillshade figure and a markdown page.

Used by ``orokit report-dataset NAME -o DIR`` (``make report``), which writes
``DIR/hillshade.png``, ``DIR/summary.json`` and, last, ``DIR/summary.md``.
"""
from __future__ import annotations

import io
import json
import logging
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from orokit._typing import PathLike
from orokit.io.atomic import write_bytes_atomic, write_text_atomic
from orokit.raster.shade import hillshade, row_cell_sizes_m
from orokit.data import portable_path

if TYPE_CHECKING:  # pragma: no cover
    import xarray as xr
    from matplotlib.axes import Axes

    from orokit.io.manifest import Dataset

logger = logging.getLogger(__name__)

__all__ = ["summarize_dem", "plot_hillshade", "write_dem_summary", "render_index"]


def summarize_dem(dem: xr.DataArray) -> dict[str, Any]:
    """Statistics and grid facts of a DEM (metres), as a JSON-friendly dict."""
    z = np.asarray(dem.values, dtype=np.float64)
    valid = np.isfinite(z)
    dx, dy = row_cell_sizes_m(dem)
    ny, nx = z.shape
    crs = dem.rio.crs
    out: dict[str, Any] = {
        "dataset": dem.attrs.get("dataset", ""),
        "title": dem.attrs.get("title", ""),
        "region": dem.attrs.get("region", ""),
        "source": portable_path(dem.attrs.get("source", "")),
        "rows": ny,
        "cols": nx,
        "crs": crs.to_string() if crs is not None else None,
        "local_grid": bool(dem.attrs.get("local_grid", crs is None)),
        "z_units_in": dem.attrs.get("z_units_in", "m"),
        "cell_size_x_m": float(np.mean(dx)),
        "cell_size_y_m": dy,
        "extent_x_km": float(np.mean(dx)) * nx / 1000.0,
        "extent_y_km": dy * ny / 1000.0,
        "valid_fraction": float(valid.mean()),
        "zero_fraction": float((z[valid] == 0).mean()) if valid.any() else 0.0,
    }
    if valid.any():
        v = z[valid]
        out.update(
            min_m=float(v.min()), max_m=float(v.max()), mean_m=float(v.mean()), std_m=float(v.std()),
            p05_m=float(np.percentile(v, 5)), p95_m=float(np.percentile(v, 95)),
        )
    return out


def plot_hillshade(ax: Axes, dem: xr.DataArray, *, max_pixels: int = 700, title: str | None = None) -> Axes:
    """Draw a hillshade tinted by elevation on ``ax``; axes in km (or degrees)."""
    import matplotlib.pyplot as plt

    step = max(1, math.ceil(max(dem.shape) / max_pixels))
    shade = hillshade(dem)[::step, ::step]
    z = np.asarray(dem.values, dtype=np.float64)[::step, ::step]
    geographic = dem.rio.crs is not None and dem.rio.crs.is_geographic
    scale = 1.0 if geographic else 1000.0
    t = dem.rio.transform()
    ny, nx = dem.shape
    extent = (t.c / scale, (t.c + t.a * nx) / scale, (t.f + t.e * ny) / scale, t.f / scale)
    ax.imshow(shade, cmap="gray", extent=extent, interpolation="nearest", vmin=0, vmax=1)
    im = ax.imshow(z, cmap="terrain", alpha=0.45, extent=extent, interpolation="nearest")
    cb = ax.figure.colorbar(im, ax=ax, shrink=0.8)
    cb.set_label("elevation (m)")
    unit = "degrees" if geographic else "km"
    ax.set_xlabel(f"x ({unit})" + (" - local grid" if dem.attrs.get("local_grid") else ""))
    ax.set_ylabel(f"y ({unit})")
    if title:
        ax.set_title(title)
    plt.setp(ax.get_xticklabels(), fontsize=8)
    plt.setp(ax.get_yticklabels(), fontsize=8)
    return ax


def _fmt(v: Any, nd: int = 1) -> str:
    return "n/a" if v is None else f"{v:,.{nd}f}"


def render_summary_markdown(summary: dict[str, Any], dataset: Dataset | None = None) -> str:
    """The markdown page of one dataset."""
    s = summary
    name = s.get("dataset") or (dataset.name if dataset else "dem")
    lines = [f"# {s.get('title') or name} (`{name}`)", ""]
    if dataset is not None:
        lines += [
            f"- Source: {dataset.primary.url}",
            f"- sha256: `{dataset.primary.sha256}`",
            f"- Licence: {dataset.licence}",
            f"- Citation: {dataset.citation}",
        ]
    grid = (
        "local metric grid (no real CRS; origin at the north-west corner)" if s["local_grid"] else f"CRS {s['crs']}"
    )
    lines += [
        f"- Grid: {s['rows']} rows x {s['cols']} columns, {grid}",
        f"- Cell size: {_fmt(s['cell_size_x_m'], 2)} m (x) x {_fmt(s['cell_size_y_m'], 2)} m (y); "
        f"extent {_fmt(s['extent_x_km'])} x {_fmt(s['extent_y_km'])} km",
        f"- Elevation units in the file: {s['z_units_in']} (converted to metres at read)",
        f"- Elevation (m): min {_fmt(s.get('min_m'))}, 5 % {_fmt(s.get('p05_m'))}, mean {_fmt(s.get('mean_m'))}, "
        f"95 % {_fmt(s.get('p95_m'))}, max {_fmt(s.get('max_m'))}, std {_fmt(s.get('std_m'))}",
        f"- Valid cells: {100 * s['valid_fraction']:.2f} %; cells at exactly 0 m: {100 * s['zero_fraction']:.2f} %",
        "",
        "![hillshade](hillshade.png)",
        "",
    ]
    return "\n".join(lines)


def _small_png(data: bytes, colors: int) -> bytes:
    """Re-encode a PNG with a palette of ``colors`` colours (no dithering)."""
    from PIL import Image

    with Image.open(io.BytesIO(data)) as im:
        pal = im.convert("RGB").quantize(colors=colors, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
    out = io.BytesIO()
    pal.save(out, format="PNG", optimize=True)
    return out.getvalue()


def write_dem_summary(
    dem: xr.DataArray, outdir: PathLike, *, dataset: Dataset | None = None, dpi: int = 100, colors: int = 128
) -> dict[str, Path]:
    """Write ``hillshade.png``, ``summary.json`` and ``summary.md`` (in that order) to ``outdir``.

    Each file is written atomically; ``summary.md`` comes last, so its presence means
    the whole summary is complete. The figure is quantised to ``colors`` palette
    colours (~90 KB). Returns the paths by kind.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    summary = summarize_dem(dem)
    fig, ax = plt.subplots(figsize=(5.2, 4.4), constrained_layout=True)
    try:
        plot_hillshade(ax, dem, max_pixels=500, title=summary.get("title") or summary.get("dataset") or None)
        buf = io.BytesIO()
        fig.savefig(buf, dpi=dpi, format="png", metadata={"Software": None})
    finally:
        plt.close(fig)
    png = write_bytes_atomic(out / "hillshade.png", _small_png(buf.getvalue(), colors))
    js = write_text_atomic(out / "summary.json", json.dumps(summary, indent=2, sort_keys=True) + "\n")
    md = write_text_atomic(out / "summary.md", render_summary_markdown(summary, dataset))
    logger.info("wrote summary of %s to %s", summary.get("dataset") or summary.get("source"), out)
    return {"png": png, "json": js, "md": md}


def render_index(summary_files: list[PathLike], index_path: PathLike) -> str:
    """Markdown index of dataset summaries (links relative to ``index_path``)."""
    base = Path(index_path).resolve().parent
    rows = []
    for f in sorted(Path(p) for p in summary_files):
        s = json.loads(Path(f).read_text(encoding="utf-8"))
        rel = Path(f).resolve().parent.relative_to(base) if Path(f).resolve().is_relative_to(base) else Path(f).parent
        name = s.get("dataset") or rel.name
        rows.append(
            f"| [{name}]({rel.as_posix()}/summary.md) | {s.get('title', '')} | {s['rows']} x {s['cols']} | "
            f"{_fmt(s['cell_size_x_m'], 2)} | {'local grid' if s['local_grid'] else s['crs']} | "
            f"{_fmt(s.get('min_m'), 0)} | {_fmt(s.get('max_m'), 0)} |"
        )
    head = [
        "# orokit report",
        "",
        "Generated by `make report`. Elevations in metres; the PNG DEMs (SRTM-3 void-filled by Jonathan de "
        "Ferranti, viewfinderpanoramas.org, via oargudo/orometry-terrains) are read on local metric grids.",
        "",
        "## Datasets",
        "",
        "| dataset | title | cells | cell (m) | grid | min (m) | max (m) |",
        "|---|---|---|---|---|---|---|",
    ]
    from orokit.reports.index import render_sections

    sections = render_sections(Path(index_path).parent)
    if sections:  # before the datasets table, so every page is one click from the index
        head = head[:4] + sections.splitlines() + [""] + head[4:]
    return "\n".join(head + rows) + "\n"
