"""Where, by wavelength and by render stage, the render of a real Divide Tree differs from its DEM.

For each region (the realism benchmark's tune group by default), at the DEM's own cell size:
the real DEM's Divide Tree (eps 30 m) is rendered with the default parameters, then with the
erosion off, then with the erosion and the noise off (the skeleton raster + the orometry
enforcement). For each raster: the ratio of its spectral power to the real DEM's in
wavelength bands (:func:`orokit.validate.landform.band_power`), slope quantiles, the
curvature interquartile range, the share of cells below the tree's lowest peak or saddle
(the tree says nothing about ground lower than that), and for the skeleton the share of
river nodes pulled down to the renderer's floor (the lowest node minus eps) by the
downstream slope of the rivers. Results: ``reports/benchmarks/render_bands.json``.

    python benchmarks/render_bands.py [--regions a,b] [--group tune|hold|all] [--seed 0] [--no-record]
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from realism import EPS, HOLD, TUNE, _extent  # noqa: E402

STAGES = {
    "default": ({}, True),
    "no erosion": ({}, False),
    "skeleton (no noise, no erosion)": ({"noise_ratio": 0.0}, False),
}


def _slope_deg(z: np.ndarray, res: float) -> np.ndarray:
    gy, gx = np.gradient(z, res)
    return np.degrees(np.arctan(np.hypot(gx, gy)))


def run_region(name: str, *, seed: int) -> dict:
    import orokit
    from orokit.data import open_dataset_dem
    from orokit.raster.params import RenderParams
    from orokit.raster.render import render_elevation
    from orokit.validate.landform import POWER_BANDS_M, band_power, landform_statistics

    dem = open_dataset_dem(name)
    res = abs(float(dem.rio.transform().a))
    zr = np.asarray(dem.values, dtype=np.float64)
    tree = orokit.analyze(dem, min_prominence_m=EPS, isolation=False).tree
    lowest = float(min(tree.peaks["elevation"].min(), tree.saddles["elevation"].min()))
    preal = band_power(zr, (res, res))
    real_stats = landform_statistics(dem).summary
    q = (0.1, 0.5, 0.9, 0.99)
    out: dict = {"cell_size_m": res, "bands_m": [list(b) for b in POWER_BANDS_M],
                 "real": {"slope_quantiles_deg": np.nanquantile(_slope_deg(zr, res), q).round(2).tolist(),
                          "curvature_iqr_per_km": real_stats["curvature_iqr_per_km"],
                          "below_lowest_node": float(np.nanmean(zr < lowest))},
                 "stages": {}}
    for stage, (kw, erosion) in STAGES.items():
        params = RenderParams(min_prominence_m=EPS, **kw)
        da, skel = render_elevation(tree, cell_size_m=res, extent=_extent(dem), erosion=erosion, params=params,
                                    rng=seed, return_skeleton=True)
        z = np.asarray(da.values, dtype=np.float64)
        stats = landform_statistics(da).summary
        rn = skel.river_network
        floor = float(rn.elevation.min())
        out["stages"][stage] = {
            "params": dataclasses.asdict(params) | {"erosion": erosion},
            "power_ratio": (band_power(z, (res, res)) / preal).round(3).tolist(),
            "slope_quantiles_deg": np.quantile(_slope_deg(z, res), q).round(2).tolist(),
            "curvature_iqr_per_km": stats["curvature_iqr_per_km"],
            "below_lowest_node": float(np.mean(z < lowest)),
            "river_nodes_at_floor": float(np.mean(rn.elevation <= floor + 1e-6)),
            "river_nodes_below_lowest_node": float(np.mean(rn.elevation < lowest)),
        }
    return out


def _markdown(results: dict) -> str:
    lines = []
    for name, r in results.items():
        bands = " | ".join(f"{lo / 1000:g}-{hi / 1000:g} km" for lo, hi in r["bands_m"])
        lines += [f"\n### {name} (power render / real by wavelength band)\n",
                  f"| raster | {bands} | slope q10/50/90/99 (deg) | curvature IQR (1/km) | cells below lowest node |"
                  " river nodes at floor |", "|---|" + "---:|" * (len(r["bands_m"]) + 4)]
        rr = r["real"]
        lines.append("| real DEM | " + " | ".join("1" for _ in r["bands_m"])
                     + f" | {'/'.join(f'{v:.1f}' for v in rr['slope_quantiles_deg'])} | {rr['curvature_iqr_per_km']:.2f}"
                     + f" | {100 * rr['below_lowest_node']:.1f} % | - |")
        for stage, s in r["stages"].items():
            lines.append(f"| {stage} | " + " | ".join(f"{v:.2f}" for v in s["power_ratio"])
                         + f" | {'/'.join(f'{v:.1f}' for v in s['slope_quantiles_deg'])}"
                         + f" | {s['curvature_iqr_per_km']:.2f} | {100 * s['below_lowest_node']:.1f} %"
                         + f" | {100 * s['river_nodes_at_floor']:.0f} % |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--regions", default=None, help="comma-separated dataset names (default: the group)")
    ap.add_argument("--group", choices=("tune", "hold", "all"), default="tune")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-record", dest="record", action="store_false")
    a = ap.parse_args(argv)
    names = a.regions.split(",") if a.regions else list({"tune": TUNE, "hold": HOLD, "all": TUNE + HOLD}[a.group])
    results = {}
    for name in names:
        t0 = time.perf_counter()
        results[name] = run_region(name, seed=a.seed) | {"load_average_1_5_15": list(os.getloadavg())}
        print(f"{name}: {time.perf_counter() - t0:.1f} s", file=sys.stderr, flush=True)
    md = _markdown(results)
    print(md)
    if a.record:
        from _record import record

        print(f"recorded {record('render_bands', {'seed': a.seed, 'eps_m': EPS, 'regions': results, 'table_markdown': md})}",
              file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
