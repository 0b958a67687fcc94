"""Fast tuning loop for the renderer: landform distances of the renders of the real Divide Trees only.

For each region (the realism benchmark's groups), the real DEM's landform statistics, its
halves' yardstick, its Divide Tree (eps 30 m) and its band powers are computed once and cached
(``--cache``, default ``~/.cache/orokit/render_realism``; never inside the repository). Each run
renders every real tree with the given ``RenderParams`` (``--render NAME=VALUE``, as
``benchmarks/realism.py``), compares it with the real DEM
(:func:`orokit.validate.landform.compare_landforms`) and prints per region the six floored
distances / targets (``X`` = over), the means a reader compares by eye (real after the slash),
the band-power ratios render / real (:func:`orokit.validate.landform.band_power`) and, with
``--roundtrip``, the tree peaks recovered and extra; then per group the regions within all six.
Nothing is recorded: ``benchmarks/realism.py`` is the benchmark of record (renders and twins).

    python benchmarks/render_realism.py [--group tune|hold|all] [--regions a,b] [--render NAME=VALUE ...]
        [--no-erosion] [--seed 0] [--roundtrip] [--json OUT.json] [--save DIR]
"""
from __future__ import annotations

import argparse
import json
import os
import pickle
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from realism import EPS, HOLD, TUNE, _extent, _render_params  # noqa: E402

SIX = ("slope_deg", "curvature_per_km", "relief_1km", "spectral_slope", "flat_share", "hypsometry")


def _cached(name: str, cache: Path) -> dict:
    """Real statistics, halves, Divide Tree and band powers of a region (computed once)."""
    import orokit
    from orokit.data import open_dataset_dem
    from orokit.validate.landform import band_power, landform_statistics, split_halves

    path = cache / f"{name}.pkl"
    if path.is_file():
        return pickle.loads(path.read_bytes())
    dem = open_dataset_dem(name)
    res = abs(float(dem.rio.transform().a))
    d = {"real": landform_statistics(dem), "halves": tuple(landform_statistics(h) for h in split_halves(dem)),
         "tree": orokit.analyze(dem, min_prominence_m=EPS).tree, "res": res, "extent": _extent(dem),
         "bands": band_power(np.asarray(dem.values, float), (res, res))}
    cache.mkdir(parents=True, exist_ok=True)
    path.write_bytes(pickle.dumps(d))
    return d


def run_region(name: str, params, *, cache: Path, seed: int, erosion: bool, roundtrip_: bool,
               save: Path | None) -> dict:
    from orokit.raster.render import render_elevation
    from orokit.validate.landform import band_power, compare_landforms, landform_statistics
    from orokit.validate.roundtrip import roundtrip

    d = _cached(name, cache)
    t0 = time.perf_counter()
    ren = render_elevation(d["tree"], cell_size_m=d["res"], extent=d["extent"], erosion=erosion, params=params,
                           rng=seed)
    t_render = time.perf_counter() - t0
    rs = landform_statistics(ren)
    cmp = compare_landforms(d["real"], rs, halves=d["halves"])
    z = np.asarray(ren.values, float)
    out = {"group": "tune" if name in TUNE else "hold" if name in HOLD else "other",
           "landform": {s: {"distance": float(cmp.loc[s, "distance"]), "target": float(cmp.loc[s, "target"]),
                            "ok": bool(cmp.loc[s, "ok"])} for s in SIX},
           "summary": rs.summary, "real": d["real"].summary,
           "band_ratio": (band_power(z, (d["res"], d["res"])) / d["bands"]).round(3).tolist(),
           "time_s": t_render, "load_average_1": os.getloadavg()[0]}
    if roundtrip_:
        rt = roundtrip(ren, d["tree"], min_prominence_m=EPS).summary()
        out["recovered"], out["extra"] = rt.get("recovered_share"), rt.get("extra_share")
    if save is not None:
        save.mkdir(parents=True, exist_ok=True)
        np.save(save / f"{name}.npy", z.astype(np.float32))
    return out


def _line(name: str, r: dict) -> str:
    s, q = r["summary"], r["real"]
    cells = " ".join(f"{v['distance']:.2f}/{v['target']:.2f}{'' if v['ok'] else 'X'}" for v in r["landform"].values())
    rt = f" rec {r['recovered']:.3f} extra {r['extra']:.3f}" if "recovered" in r else ""
    return (f"{name:18s} {cells} | slope {s['mean_slope_deg']:.1f}/{q['mean_slope_deg']:.1f} "
            f"p90 {s['p90_slope_deg']:.1f}/{q['p90_slope_deg']:.1f} flat {s['flat_share']:.3f}/{q['flat_share']:.3f} "
            f"curv iqr {s['curvature_iqr_per_km']:.2f}/{q['curvature_iqr_per_km']:.2f} "
            f"beta {s['spectral_slope']:.2f}/{q['spectral_slope']:.2f} bands {r['band_ratio']}{rt} {r['time_s']:.1f} s")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--group", choices=("tune", "hold", "all"), default="tune")
    ap.add_argument("--regions", default=None, help="comma-separated dataset names (default: the group)")
    ap.add_argument("--render", action="append", default=[], metavar="NAME=VALUE",
                    help="a RenderParams field (repeatable), e.g. detail_gain=0.5")
    ap.add_argument("--no-erosion", dest="erosion", action="store_false")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--roundtrip", action="store_true", help="also re-analyse: tree peaks recovered and extra")
    ap.add_argument("--cache", type=Path, default=Path.home() / ".cache" / "orokit" / "render_realism")
    ap.add_argument("--json", type=Path, default=None, help="write the results here")
    ap.add_argument("--save", type=Path, default=None, help="save each render as DIR/<region>.npy")
    a = ap.parse_args(argv)
    names = a.regions.split(",") if a.regions else list({"tune": TUNE, "hold": HOLD, "all": TUNE + HOLD}[a.group])
    params = _render_params(a.render)
    results = {}
    for name in names:
        results[name] = run_region(name, params, cache=a.cache, seed=a.seed, erosion=a.erosion,
                                   roundtrip_=a.roundtrip, save=a.save)
        print(_line(name, results[name]), flush=True)
    for grp in ("tune", "hold"):
        rows = [r for r in results.values() if r["group"] == grp]
        if rows:
            per = [sum(r["landform"][s]["ok"] for r in rows) for s in SIX]
            six = sum(all(v["ok"] for v in r["landform"].values()) for r in rows)
            print(f"{grp}: all six {six}/{len(rows)}; per statistic ({', '.join(SIX)}) {per}; "
                  f"load {os.getloadavg()[0]:.1f}")
    if a.json is not None:
        a.json.write_text(json.dumps({"render": a.render, "seed": a.seed, "erosion": a.erosion, "regions": results},
                                     indent=1, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
