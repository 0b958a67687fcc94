"""Landform realism of rendered terrain: real DEM vs render of its real tree vs free twin.

For every shared DEM (the manifest's 13 region crops), at the DEM's own cell size:

- *render*: the real DEM's own Divide Tree (``orokit.analyze``, eps 30 m) rendered on the
  DEM's extent (what ``orokit render TREE --like DEM`` does, default parameters);
- *twin*: a tree synthesized from the region's terrain type on a domain of the DEM's size
  (what ``orokit synthesize --type T --like DEM`` does), rendered with the defaults;
  with ``--control-elevation like`` the *relief twin* instead, the real DEM's elevation as C_H
  (``orokit synthesize --type T --like DEM --control-elevation like``, the relief pages of
  ``make roundtrip``): twins only, never recorded (``--json`` keeps the run).

Each is compared with the real DEM by :func:`orokit.validate.landform.compare_landforms`
(distance, real north/south halves yardstick, target = max(2 x halves, floor)), and
re-analysed for the orometry (tree peaks recovered, extra peaks). Regions are split in
two fixed groups: ``tune`` (used while choosing renderer defaults) and ``hold`` (only
checked), reported apart. Results: ``reports/benchmarks/realism.json``.

    python benchmarks/realism.py [--regions a,b] [--group tune|hold|all] [--figures DIR] [--no-erosion]
        [--seed N] [--twin-only] [--control-elevation like] [--synthesis NAME=VALUE ...] [--render NAME=VALUE ...]
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

#: fixed before any tuning: defaults are chosen on TUNE only, HOLD is checked afterwards
TUNE = ("alaska", "andes-chile", "appalachians", "gobi", "himalaya-everest", "norway")
HOLD = ("andes-aconcagua", "highlands", "himalaya-annapurna", "karakoram", "pyrenees", "rockies", "sahara")
EPS = 30.0
#: the region model of the reclassification: a build product (`make region-model`), not tracked
REGION_MODEL = Path(__file__).resolve().parents[1] / "models" / "regions-10km.skops"
#: shares of the highest peaks whose position inside the border is recorded (``top_interior``)
TOP_SHARES = (0.02, 0.05, 0.1)


def _extent(dem) -> tuple[float, float, float, float]:
    t = dem.rio.transform()
    ny, nx = dem.shape
    xs, ys = (t.c, t.c + t.a * nx), (t.f, t.f + t.e * ny)
    return (min(xs), min(ys), max(xs), max(ys))


def _table(df) -> dict:
    return {k: {c: (bool(v) if c == "ok" else float(v)) for c, v in row.items()} for k, row in df.iterrows()}


def run_region(name: str, *, seed: int, erosion: bool, figures: Path | None, params=None, model=None,
               synthesis=None, render_real: bool = True, relief: bool = False) -> dict:
    import orokit
    from orokit.data import open_dataset_dem
    from orokit.raster.params import RenderParams
    from orokit.raster.render import render_elevation
    from orokit.raster.skeleton import tree_extent
    from orokit.synthesis.fidelity import ridge_statistics
    from orokit.synthesis.terrain_type import TerrainType
    from orokit.synthesis.tree import synthesize_divide_tree
    from orokit.validate.landform import compare_landforms, landform_statistics, split_halves
    from orokit.validate.roundtrip import roundtrip
    from orokit.cli.synthesize import texture_params
    from orokit.raster.noise import texture_spectrum

    params = params or RenderParams(min_prominence_m=EPS)
    dem = open_dataset_dem(name)
    res = abs(float(dem.rio.transform().a))
    ny, nx = dem.shape
    real = landform_statistics(dem)
    halves = tuple(landform_statistics(h) for h in split_halves(dem))
    result = orokit.analyze(dem, min_prominence_m=EPS)
    tree = result.tree
    out: dict = {"shape": [ny, nx], "cell_size_m": res, "real": real.summary, "tree_peaks": int(tree.n_peaks)}

    ren = None
    if render_real:
        t0 = time.perf_counter()
        ren = render_elevation(tree, cell_size_m=res, extent=_extent(dem), erosion=erosion, params=params, rng=seed)
        t_render = time.perf_counter() - t0
        rs = landform_statistics(ren)
        rt = roundtrip(ren, tree, min_prominence_m=EPS).summary()
        out["render"] = {"time_s": t_render, "summary": rs.summary,
                         "landform": _table(compare_landforms(real, rs, halves=halves)),
                         "recovered": rt.get("recovered_share"), "extra": rt.get("extra_share")}

    # the type as `orokit type` makes it from the DEM: orometry + the DEM's texture
    ttype = TerrainType.from_analysis(result, name=name).with_texture(*texture_spectrum(dem.values, res))
    t0 = time.perf_counter()
    c_h = np.asarray(dem.values, dtype=float) if relief else None  # row 0 north, as the CLI's 'like'
    ttree = synthesize_divide_tree(ttype, size_m=(nx * res, ny * res), control_elevation=c_h, params=synthesis,
                                   rng=seed)
    twin = render_elevation(ttree, cell_size_m=res, extent=tree_extent(ttree), erosion=erosion,
                            params=dataclasses.replace(params, **texture_params(ttype)), rng=seed)
    t_twin = time.perf_counter() - t0
    ts = landform_statistics(twin)
    twin_analysis = orokit.analyze(twin, min_prominence_m=EPS)
    rt2 = roundtrip(twin, ttree, min_prominence_m=EPS, model=model, expected_label=name if model else None,
                    analysis=twin_analysis).summary()
    out["twin"] = {"time_s": t_twin, "summary": ts.summary,
                   "landform": _table(compare_landforms(real, ts, halves=halves)),
                   "recovered": rt2.get("recovered_share"), "extra": rt2.get("extra_share"),
                   "texture": dict(ttype.texture or {}),
                   "disk_accuracy": rt2.get("disk_accuracy"), "n_disks": rt2.get("n_disks"),
                   "vote": rt2.get("predicted"),
                   "disk_drift": disk_drift(dem, result, twin, twin_analysis)}
    # steepness of the trees themselves, before rendering (the real tree vs the twin's)
    out["ridges"] = {"real": ridge_statistics(tree), "twin": ridge_statistics(ttree),
                     "contrast": {"real": ttype.ridge_contrast, "twin": ttree.attrs.get("ridge_contrast")},
                     "neighbour_gradient_fit": ttree.attrs.get("neighbour_gradient"),
                     "max_ridge_slope": ttree.attrs.get("max_ridge_slope")}
    out["tree_fidelity"] = tree_fidelity(tree, ttree)
    # the channels' slope by drainage area and the > 60 deg cells (not among the six; issue 11's trunks and walls)
    out["channels"] = {k: channels(v) for k, v in (("real", dem), ("render", ren), ("twin", twin)) if v is not None}
    if figures is not None:
        panels = {"real DEM": dem, "render of its real tree": ren, "free twin": twin}
        _figure(figures / f"{name}.png", name, {k: v for k, v in panels.items() if v is not None})
    return out


def channels(dem) -> dict:
    """Channel slope by drainage area (:func:`orokit.metrics.landform.channel_slopes`) and the share of cells
    steeper than 60 degrees."""
    from orokit.metrics.landform import channel_slopes, slope_and_relief

    slope, _ = slope_and_relief(dem)
    return {"slope_by_area": channel_slopes(dem), "steep_60_share": float(np.nanmean(slope > 60.0))}


def tree_fidelity(real_tree, twin_tree) -> dict:
    """How far the twin tree's orometry lies from the real tree's, before rendering: W1 of log prominence and
    of :func:`orokit.synthesis.saddles.plain_dominance` (both trees pruned at ``EPS``), and their medians."""
    from scipy.stats import wasserstein_distance

    from orokit.synthesis.orometry import planar_xy, tree_orometry
    from orokit.synthesis.saddles import plain_dominance

    vals = []
    for t in (real_tree.prune(EPS), twin_tree.prune(EPS)):
        x, y = planar_xy(t.peaks["x"].to_numpy(float), t.peaks["y"].to_numpy(float), t.crs)
        z = t.peaks["elevation"].to_numpy(float)
        s = t.saddles["elevation"].to_numpy(float)[t.edges["saddle"].to_numpy(np.int64)]
        q = plain_dominance(z, x, y, t.edges["peak_a"].to_numpy(np.int64), t.edges["peak_b"].to_numpy(np.int64), s)
        prom = tree_orometry(t)["prominence"].to_numpy(float)
        keyed = np.isfinite(q)
        vals.append((np.log(prom[keyed]), q[keyed]))
    (lp_r, q_r), (lp_t, q_t) = vals
    return {"log_prominence_w1": float(wasserstein_distance(lp_r, lp_t)),
            "plain_dominance_w1": float(wasserstein_distance(q_r, q_t)),
            "plain_dominance_median": [float(np.median(q_r)), float(np.median(q_t))],
            "prominence_q10_q50_q90_m": [[float(v) for v in np.exp(np.quantile(lp, [0.1, 0.5, 0.9]))]
                                         for lp in (lp_r, lp_t)]}


def disk_drift(real_dem, real_analysis, twin, twin_analysis, radius_m: float = 10_000.0) -> dict:
    """How the twin's 10 km disks differ from the real DEM's, measured on both rasters' analyses.

    ``tv``: total-variation distance between the mean disk histograms of each of the paper's
    ten Table 1 features (``orokit features --feature-set paper``: relevance, relative prominence
    and relative elevation are the disk-relative ones); ``w``: Wasserstein distance between the
    per-disk distributions of log peak count, log max prominence and ``top_rank``
    (:func:`orokit.synthesis.disks.disk_statistics`, disks on a 1 km grid); ``top_interior``:
    per raster, the share of its highest 2 %, 5 % and 10 % of peaks lying >= 10 km inside its
    border (:func:`orokit.synthesis.disks.interior_share`; the classifier's disks see only that
    interior) and the interior's share of the area.
    """
    import warnings

    from orokit.classify.features import features_from_dem
    from orokit.sampling.feature_sets import FeatureSet
    from orokit.synthesis.disks import disk_statistics, interior_share
    from scipy.stats import wasserstein_distance

    fs = FeatureSet.paper()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tabs = [features_from_dem(d, radius_m=radius_m, analysis=a, feature_set=fs, rng=0)
                for d, a in ((real_dem, real_analysis), (twin, twin_analysis))]
    tv = {}
    for group, cols in fs.groups().items():
        if all(len(t) for t in tabs):
            m = [t[cols].mean().to_numpy(float) for t in tabs]
            m = [v / v.sum() if v.sum() > 0 else v for v in m]
            tv[group] = round(float(0.5 * np.abs(m[0] - m[1]).sum()), 4)
    per = []
    top_interior: dict = {}
    for label, d, a in (("real", real_dem, real_analysis), ("twin", twin, twin_analysis)):
        pk = a.peaks
        pk = pk[pk["prominence"].to_numpy(float) >= EPS]
        top_interior[label] = [round(interior_share(pk["x"].to_numpy(float), pk["y"].to_numpy(float),
                                                    pk["elevation"].to_numpy(float), _extent(d), top=q,
                                                    margin_m=radius_m), 4) for q in TOP_SHARES]
        per.append(disk_statistics(pk["x"].to_numpy(float), pk["y"].to_numpy(float), pk["elevation"].to_numpy(float),
                                   pk["prominence"].to_numpy(float), _extent(d), radius_m=radius_m,
                                   min_prominence_m=EPS))
    w = {"log_peaks": wasserstein_distance(np.log1p(per[0]["peaks"]), np.log1p(per[1]["peaks"])),
         "log_max_prominence": wasserstein_distance(np.log1p(per[0]["max_prominence_m"]),
                                                    np.log1p(per[1]["max_prominence_m"])),
         "top_rank": wasserstein_distance(per[0]["top_rank"], per[1]["top_rank"])}
    x0, y0, x1, y1 = _extent(real_dem)
    top_interior["area"] = round(max(x1 - x0 - 2 * radius_m, 0) * max(y1 - y0 - 2 * radius_m, 0)
                                 / ((x1 - x0) * (y1 - y0)), 4)
    return {"tv": tv, "w": {k: round(float(v), 4) for k, v in w.items()}, "n_disks": [len(t) for t in tabs],
            "top_interior": top_interior}


def _figure(path: Path, name: str, panels: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from orokit.reports.landform import plot_landforms

    path.parent.mkdir(parents=True, exist_ok=True)
    fig = plot_landforms(panels, title=name)
    fig.savefig(path, dpi=150)
    plt.close(fig)


def _markdown(results: dict) -> str:
    from orokit.validate.landform import FLOORS

    stats = list(FLOORS) + ["relief_5km", "low_slope_deg", "drainage_share", "drainage_density"]
    lines = []
    for kind in ("render", "twin"):
        if not any(kind in r for r in results.values()):
            continue
        lines.append(f"\n### {kind}: distance / target (x = over target)\n")
        lines.append("| region | group | " + " | ".join(stats) + " | recovered | extra | s |")
        lines.append("|---|---|" + "---:|" * (len(stats) + 3))
        for name, r in results.items():
            lf = r[kind]["landform"]
            cells = [f"{lf[s]['distance']:.3g}/{lf[s]['target']:.3g}{'' if lf[s]['ok'] else ' x'}" for s in stats]
            lines.append(f"| {name} | {r['group']} | " + " | ".join(cells)
                         + f" | {100 * (r[kind]['recovered'] or 0):.1f} | {100 * (r[kind]['extra'] or 0):.1f}"
                         + f" | {r[kind]['time_s']:.1f} |")
        for grp in ("tune", "hold"):
            rows = [r for r in results.values() if r["group"] == grp]
            if rows:
                met = [sum(r[kind]["landform"][s]["ok"] for r in rows) for s in stats]
                lines.append(f"| **{grp}: regions within target** | | " + " | ".join(f"{m}/{len(rows)}" for m in met)
                             + " | | | |")
    return "\n".join(lines)


def _drift_markdown(results: dict) -> str:
    """Per region: how far the twin's 10 km disks are from the real ones (see :func:`disk_drift`)."""
    tv_cols = ["relevance", "relative_prominence", "relative_elevation", "prominence", "saddle_distance"]
    w_cols = ["log_peaks", "log_max_prominence", "top_rank"]
    lines = ["### twin vs real 10 km disks: TV distance of mean disk histograms, W distance of per-disk values; "
             "share of the highest 2 % / 10 % of peaks >= 10 km inside the border, real / twin (area: the interior's "
             "share of the area)", "",
             "| region | " + " | ".join(f"TV {c}" for c in tv_cols) + " | " + " | ".join(f"W {c}" for c in w_cols)
             + " | top 2 % inside | top 10 % inside | area |",
             "|---|" + "---:|" * (len(tv_cols) + len(w_cols) + 3)]
    for name, r in results.items():
        d = r["twin"].get("disk_drift") or {}
        tv, w, ti = d.get("tv", {}), d.get("w", {}), d.get("top_interior")
        inside = (" | ".join(f"{ti['real'][i]:.2f} / {ti['twin'][i]:.2f}" for i in (0, 2)) + f" | {ti['area']:.2f}"
                  if ti else "- | - | -")
        lines.append(f"| {name} | " + " | ".join(f"{tv[c]:.2f}" if c in tv else "-" for c in tv_cols) + " | "
                     + " | ".join(f"{w[c]:.2f}" if c in w else "-" for c in w_cols) + f" | {inside} |")
    return "\n".join(lines)


def _ridges_markdown(results: dict) -> str:
    """Per region: the real tree's and the twin tree's steepness (:func:`ridge_statistics`)."""
    cols = ("neighbour_gradient", "half_ridge_slope", "ridge_slope", "higher_end_drop_m", "ridge_length_m",
            "forced_prominence_m")
    lines = ["### trees before rendering, real / twin: median and 90th percentile of the elevation gradient "
             "to the nearest peak, of each ridge half's drop to its saddle, and of the ridge's drops over its length "
             "(m/m), of the drop from each ridge's higher end to its saddle, of the ridge length and of the least "
             "prominence the tree's peak layout allows (m)",
             "", "| region | " + " | ".join(f"{c} median | {c} p90" for c in cols) + " |",
             "|---|" + "---:|" * (2 * len(cols))]
    for name, r in results.items():
        rd = r.get("ridges")
        if not rd:
            continue
        digits = {c: 0 if c.endswith("_m") else 2 for c in cols}
        cells = [f"{rd['real'][c][i]:.{digits[c]}f} / {rd['twin'][c][i]:.{digits[c]}f}" if c in rd["twin"] and c in rd["real"] else "-"
                 for c in cols for i in (0, 1)]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _reclassification(results: dict, real_accuracy: Path) -> dict:
    """Twins' disks classified as their own region vs the real disks' spatial hold-out accuracy."""
    import pandas as pd

    real = pd.read_csv(real_accuracy).set_index("region") if real_accuracy.is_file() else None
    rows, met, known = [], 0, 0
    for name, r in results.items():
        acc = r["twin"].get("disk_accuracy")
        sp = float(real.loc[name, "spatial_accuracy_%"]) if real is not None and name in real.index else float("nan")
        ok = acc is not None and np.isfinite(sp) and 100.0 * float(acc) >= sp
        known += int(np.isfinite(sp))
        met += int(ok)
        rows.append(f"| {name} | {r['twin'].get('n_disks')} | "
                    f"{'-' if acc is None else f'{100 * float(acc):.0f}'} | {'-' if not np.isfinite(sp) else f'{sp:.0f}'} | "
                    f"{r['twin'].get('vote')} | {'yes' if ok else 'no'} |")
    md = "\n".join(["### reclassification: twin disks right % vs real disks right % (spatial hold-out)", "",
                    "| region | twin disks | twin right % | real right % (spatial) | twin vote | twin >= real |",
                    "|---|---:|---:|---:|---|---|", *rows, "",
                    f"Twins at least as often right as the real disks: {met} of {known} regions the model knows."])
    return {"met": met, "known": known, "markdown": md}


def _pairs(pairs: list[str]) -> dict:
    """``NAME=VALUE`` strings as a dict (values parsed as JSON, else kept as text)."""
    kw = {}
    for pair in pairs:
        key, _, val = pair.partition("=")
        try:
            kw[key] = json.loads(val)
        except json.JSONDecodeError:
            kw[key] = val
    return kw


def _synthesis_params(pairs: list[str]):
    """SynthesisParams from ``NAME=VALUE`` strings."""
    from orokit.synthesis.tree import SynthesisParams

    return SynthesisParams(**_pairs(pairs))


def _render_params(pairs: list[str]):
    """RenderParams (eps 30 m) from ``NAME=VALUE`` strings; lists become tuples."""
    from orokit.raster.params import RenderParams

    kw = {k: tuple(v) if isinstance(v, list) else v for k, v in _pairs(pairs).items()}
    return RenderParams(**{"min_prominence_m": EPS, **kw})


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--regions", default=None, help="comma-separated dataset names (default: the group)")
    ap.add_argument("--group", choices=("tune", "hold", "all"), default="all")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-erosion", dest="erosion", action="store_false")
    ap.add_argument("--twin-only", dest="render_real", action="store_false",
                    help="skip the render of the real tree (synthesis experiments); never recorded")
    ap.add_argument("--control-elevation", choices=("like",), default=None,
                    help="'like': relief twins, the real DEM's elevation as C_H (twins only; never recorded)")
    ap.add_argument("--synthesis", action="append", default=[], metavar="NAME=VALUE",
                    help="a SynthesisParams field for the twins (repeatable), e.g. void_weight=1.0")
    ap.add_argument("--render", action="append", default=[], metavar="NAME=VALUE",
                    help="a RenderParams field for both renders (repeatable), e.g. texture_gain=0.2; recorded "
                    "as 'render' (empty: the defaults)")
    ap.add_argument("--figures", type=Path, default=None, help="write real / render / twin hillshades here")
    ap.add_argument("--no-record", dest="record", action="store_false",
                    help="do not write reports/benchmarks/realism.json")
    ap.add_argument("--json", type=Path, default=None, help="also write the results to this file")
    ap.add_argument("--model", type=Path, default=REGION_MODEL,
                    help="region model: the twins' disks are classified (reclassification); the default is a build "
                    "product: `make region-model`")
    ap.add_argument("--no-model", dest="model", action="store_const", const=None,
                    help="no reclassification (no region model needed)")
    ap.add_argument("--real-accuracy", type=Path,
                    default=Path(__file__).resolve().parents[1] / "reports" / "classification" / "tables"
                    / "per_class_10km.csv", help="real disks' per-region accuracy (classification report)")
    ap.add_argument("--combine", type=Path, nargs="+", default=None, metavar="JSON",
                    help="no run: merge the regions of earlier --json outputs (same seed and parameters, e.g. the "
                    "groups run in parallel), print and record them as one run")
    a = ap.parse_args(argv)
    groups = {"tune": TUNE, "hold": HOLD, "all": TUNE + HOLD}
    names = a.regions.split(",") if a.regions else list(groups[a.group])
    results: dict = {}
    model = None
    if a.model is not None:
        if not a.model.is_file():
            how = "build it with `make region-model` (about 3 min)" if a.model == REGION_MODEL else "check the path"
            raise SystemExit(f"region model {a.model} not found: {how}, or pass --no-model to skip the "
                             "reclassification")
        from orokit.classify.model import load_model

        model = load_model(a.model)
    synthesis = _synthesis_params(a.synthesis)
    if a.combine:
        docs = [json.loads(p.read_text()) for p in a.combine]
        keys = ("seed", "erosion", "synthesis", "render", "model", "control_elevation")
        if any(tuple(d.get(k) for k in keys) != tuple(docs[0].get(k) for k in keys) for d in docs):
            raise SystemExit(f"--combine: the runs differ in {', '.join(keys)}; combine only runs of one setting")
        a.seed, a.erosion, a.control_elevation = docs[0]["seed"], docs[0]["erosion"], docs[0].get("control_elevation")
        synthesis = _synthesis_params([f"{k}={json.dumps(v)}" for k, v in docs[0]["synthesis"].items()])
        a.render = [f"{k}={json.dumps(v)}" for k, v in (docs[0].get("render") or {}).items()]
        for d in docs:
            results.update(d["regions"])
        names = []
        a.render_real = all("render" in r for r in results.values())
    render = _render_params(a.render)
    relief = a.control_elevation == "like"
    if relief:
        a.render_real = False  # the render of the real tree does not depend on C_H
    for name in names:
        t0 = time.perf_counter()
        r = run_region(name, seed=a.seed, erosion=a.erosion, figures=a.figures, model=model, synthesis=synthesis,
                       render_real=a.render_real, params=render, relief=relief)
        r["group"] = "tune" if name in TUNE else "hold" if name in HOLD else "other"
        r["load_average_1_5_15"] = list(os.getloadavg())
        results[name] = r
        print(f"{name}: {time.perf_counter() - t0:.1f} s", file=sys.stderr, flush=True)
    md = _markdown(results) + "\n\n" + _drift_markdown(results) + "\n\n" + _ridges_markdown(results)
    recl = _reclassification(results, a.real_accuracy) if model is not None else None
    if recl:
        md += "\n\n" + recl["markdown"]
    print(md)
    doc = {"seed": a.seed, "erosion": a.erosion, "eps_m": EPS, "control_elevation": a.control_elevation,
           "synthesis": synthesis.to_dict(),
           "render": _pairs(a.render), "tune": list(TUNE), "hold": list(HOLD),
           "model": None if model is None else str(a.model.name), "regions": results,
           "reclassification": recl, "table_markdown": md}
    if a.json is not None:
        a.json.write_text(json.dumps(doc, indent=1, default=float))
    if a.record and (not a.regions or a.combine) and a.render_real:
        from _record import record

        print(f"recorded {record('realism', doc)}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
