"""Spokes and walls: the ground's cross-section across the real Divide Tree's pieces, real DEM vs renders.

For each region, the median drop of the ground beside every straight tree piece (peak -> saddle) at perpendicular
offsets (:func:`orokit.validate.crest.crest_sections`; points every 200 m from 1 km past the peak to 400 m before
the saddle; each centred on the highest ground within ``--search`` 300 m of the line, where a real crest
meanders) and the median crest width (first offset where the ground lies 25 m below the line,
:func:`orokit.validate.crest.crest_width`), on the real DEM and on renders of its tree saved by
``benchmarks/render_realism.py --save DIR`` (one ``DIR/<region>.npy`` per region, same grid as the DEM). Pieces
are split into those ``ridge_plateau_spread`` 0.25 / ``ridge_plateau_relief_m`` 300 selects
(:func:`orokit.raster.skeleton.spread_pieces`: volcanoes on a plateau; with ``--spacing M`` also
:func:`orokit.raster.skeleton.lone_pieces`, ``ridge_tail_spacing_m``) and the others. Nothing is recorded.

    python benchmarks/crest_sections.py --saved LABEL=DIR [--saved LABEL=DIR ...] [--group all] [--regions a,b]
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from realism import HOLD, TUNE  # noqa: E402
from render_realism import _cached  # noqa: E402

DROP_M = 25.0


def region_sections(name: str, grids: dict[str, Path], cache: Path, search_m: float,
                    spacing_m: float | None = None) -> list[str]:
    from orokit.data import open_dataset_dem
    from orokit.raster.rivers import ridge_segments
    from orokit.raster.skeleton import _tree_arrays, lone_pieces, spread_pieces
    from orokit.validate.crest import crest_sections, crest_width

    d = _cached(name, cache)
    xmin, _, _, ymax = d["extent"]
    p, s, e = _tree_arrays(d["tree"])
    nodes = np.concatenate([p, s])
    rs = ridge_segments(p, s, e)
    sel = spread_pieces(nodes[rs.node1], p, s, 0.25, min_relief_m=300.0)
    if spacing_m is not None:
        sel &= lone_pieces(nodes[rs.node0], p, spacing_m)
    rasters = {"real": np.asarray(open_dataset_dem(name).values, float)}
    rasters.update({k: np.load(v / f"{name}.npy").astype(float) for k, v in grids.items()
                    if (v / f"{name}.npy").is_file()})
    lines = []
    for label, z in rasters.items():
        cs = crest_sections(z, (xmin, ymax, d["res"]), nodes[rs.node0, :2], nodes[rs.node1, :2], search_m=search_m)
        w = crest_width(cs, DROP_M)
        for grp, m in (("selected", sel), ("others", ~sel)):
            pts = m[cs.piece]
            if not pts.any():
                continue
            med = cs.median(m)
            lines.append(f"{name:18s} {label:10s} {grp:8s} n {int(pts.sum()):5d} drop "
                         + " ".join(f"{o:.0f}:{v:6.1f}" for o, v in zip(cs.offsets_m, med))
                         + f" | width{DROP_M:.0f} median {np.median(w[pts]):.0f} m")
    return lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--saved", action="append", default=[], metavar="LABEL=DIR",
                    help="renders saved by render_realism.py --save DIR")
    ap.add_argument("--group", choices=("tune", "hold", "all"), default="all")
    ap.add_argument("--regions", default=None, help="comma-separated dataset names (default: the group)")
    ap.add_argument("--search", type=float, default=300.0,
                    help="centre each section on the highest ground within this many metres of the line (0: on it)")
    ap.add_argument("--spacing", type=float, default=None,
                    help="select only pieces whose peak stands alone too (ridge_tail_spacing_m, metres)")
    ap.add_argument("--cache", type=Path, default=Path.home() / ".cache" / "orokit" / "render_realism")
    a = ap.parse_args(argv)
    grids = {}
    for kv in a.saved:
        label, sep, path = kv.partition("=")
        if not sep or not Path(path).is_dir():
            ap.error(f"--saved wants LABEL=DIR with an existing directory, got {kv!r}")
        grids[label] = Path(path)
    names = a.regions.split(",") if a.regions else {"tune": TUNE, "hold": HOLD, "all": TUNE + HOLD}[a.group]
    for name in names:
        print("\n".join(region_sections(name, grids, a.cache, a.search, a.spacing)), flush=True)
    print(f"load {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
