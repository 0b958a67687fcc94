"""Map of a classified DEM: every disk coloured by its predicted region over the hillshade."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from orokit._typing import PathLike

DPI = 110


def plot_classification_map(ax: Any, dem: Any, disks: Any, classes: list[str], *, title: str | None = None) -> Any:
    """Draw the DEM's hillshade and each disk (polygon) coloured by its predicted class.

    ``disks`` is the GeoDataFrame of :func:`orokit.classify.predict.disk_map` (columns
    ``predicted``, ``proba_<class>``, polygon geometry in the DEM's CRS). Outline width
    and the centre dot's size grow with the disk's top probability. Axes in km (or degrees), as the
    hillshade of :func:`orokit.reports.dem_summary.plot_hillshade`.
    """
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    from orokit.reports.dem_summary import plot_hillshade

    plot_hillshade(ax, dem, title=title)
    geographic = dem.rio.crs is not None and dem.rio.crs.is_geographic
    scale = 1.0 if geographic else 1000.0
    cmap = plt.get_cmap("tab20")
    colours = {c: cmap(k % 20) for k, c in enumerate(classes)}
    colours["unknown"] = (0.3, 0.3, 0.3, 1.0)
    # least confident first, so confident disks are drawn on top
    order = np.argsort(disks["confidence"].to_numpy(float)) if len(disks) else np.zeros(0, np.int64)
    for i in order:
        row = disks.iloc[int(i)]
        geom = row.geometry
        polys = getattr(geom, "geoms", [geom])
        for poly in polys:
            x, y = np.asarray(poly.exterior.xy)
            col = colours.get(row["predicted"], (0, 0, 0, 1))
            conf = float(row["confidence"])
            ax.fill(x / scale, y / scale, color=col, alpha=0.03 + 0.07 * conf, linewidth=0)
            ax.plot(x / scale, y / scale, color=col, linewidth=0.4 + 0.8 * conf, alpha=0.8)
        ax.scatter([row["x"] / scale], [row["y"] / scale], s=15 + 60 * float(row["confidence"]),
                   color=colours.get(row["predicted"], (0, 0, 0, 1)), edgecolors="black", linewidths=0.5, zorder=5)
    present = [c for c in classes + ["unknown"] if len(disks) and (disks["predicted"] == c).any()]
    ax.legend(handles=[Patch(color=colours[c], label=f"{c} ({int((disks['predicted'] == c).sum())})")
                       for c in present], fontsize=7, loc="upper left", bbox_to_anchor=(1.25, 1.0),
              title="predicted (disks)", title_fontsize=7)
    return ax


def write_classification_map_png(dem: Any, disks: Any, classes: list[str], path: PathLike, *,
                                 title: str | None = None) -> Path:
    """Save :func:`plot_classification_map` as a PNG (atomic)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    from orokit.io.atomic import atomic_path

    path = Path(path)
    fig, ax = plt.subplots(figsize=(9, 6.5))
    plot_classification_map(ax, dem, disks, classes, title=title)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=DPI, bbox_inches="tight", format="png")
    plt.close(fig)
    return path
