"""North-half-trained / south-half-classified protocol, exactly as a new user runs it (issue 12).

Usage: python benchmarks/classification_halves.py [--features terrain orometry paper] [--classifier rf]
       [--radius 10km] [--out reports/classification/halves.md]

For every DEM of the manifest (the 13 shared crops): the north half and the south half
are written as GeoTIFFs to a temporary folder (float32 metres, NaN nodata; the crops have
no published location, so they get a UTM CRS with the manifest's cell size). Then,
through the command line only:

1. ``orokit features north/*.tif -o f.parquet --radius R --features F``
2. ``orokit train f.parquet -o m.skops --drop-small-classes`` (default evaluation)
3. ``orokit classify m.skops south/<name>.tif --json`` for every region

A region counts when it has >= 2 training disks (it is in the model) and >= 2 disks in
its south half ("enough disks"). The terrain answer is the model's label (summed
log-probability over the south disks; 'unknown' below the model's threshold) and the
best class. Nothing is tuned on the south halves. The table goes to ``--out`` (Markdown)
and every number, with timings and the machine load, to
``reports/benchmarks/classification_halves.json``.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _orokit() -> str:
    exe = Path(sys.executable).with_name("orokit")
    return str(exe) if exe.exists() else "orokit"


def _child_cpu() -> float:
    """CPU seconds (user + system) of the finished child processes so far."""
    import resource

    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def run_cli(*args: str) -> str:
    res = subprocess.run([_orokit(), *args], capture_output=True, text=True)
    if res.returncode != 0:
        raise SystemExit(f"orokit {' '.join(args)} failed ({res.returncode}):\n{res.stdout}\n{res.stderr}")
    return res.stdout


def write_halves(folder: Path) -> list[str]:
    """North and south halves of every manifest DEM as GeoTIFFs; returns the region names."""
    import numpy as np
    import rioxarray  # noqa: F401
    from rasterio.transform import Affine

    from orokit.data import load_manifest, open_dataset_dem

    names = [d.name for d in load_manifest().dems() if d.name != "pysheds-dem"]
    for half in ("north", "south"):
        (folder / half).mkdir(parents=True, exist_ok=True)
    for name in names:
        dem = open_dataset_dem(name)
        t = dem.rio.transform()
        dx, dy = abs(t.a), abs(t.e)
        n = dem.shape[0] // 2
        for half, sl in (("north", slice(0, n)), ("south", slice(n, None))):
            part = dem.isel(y=sl).astype(np.float32)
            row0 = 0 if half == "north" else n
            tr = Affine(dx, 0.0, 500_000.0, 0.0, -dy, 5_000_000.0 - row0 * dy)
            part = part.rio.write_crs("EPSG:32633").rio.write_transform(tr).rio.write_nodata(np.nan)
            part.attrs = {"units": "m"}
            part.rio.to_raster(folder / half / f"{name}.tif")
    return names


def protocol(folder: Path, names: list[str], *, feature_set: str, classifier: str, radius: str) -> dict:
    feats = folder / f"features_{feature_set}.parquet"
    model = folder / f"model_{feature_set}_{classifier}.skops"
    t0 = time.perf_counter()
    run_cli("-q", "features", *[str(folder / "north" / f"{n}.tif") for n in names], "-o", str(feats),
            "--radius", radius, "--features", feature_set, "--no-progress", "--overwrite")
    t_features = time.perf_counter() - t0
    t0, c0 = time.perf_counter(), _child_cpu()
    run_cli("-q", "train", str(feats), "-o", str(model), "--drop-small-classes", "--classifier", classifier,
            "--no-progress", "--overwrite")
    t_train, c_train = time.perf_counter() - t0, _child_cpu() - c0
    load_train = list(os.getloadavg())
    md = json.loads(Path(str(model) + ".json").read_text())
    classes = md["classes"]
    rows = []
    for name in names:
        row = {"region": name, "training_disks": int(md["n_training_disks"].get(name, 0)), "in_model": name in classes}
        try:
            out = run_cli("-q", "classify", str(model), str(folder / "south" / f"{name}.tif"), "--json")
            js = json.loads(out[out.index("{"):])
            row.update(south_disks=js["n_disks"], label=js["label"], best=js["best"],
                       confidence=js["confidence"],
                       disk_accuracy=(sum(d["predicted"] == name for d in js["disks"]) / js["n_disks"]
                                      if js["n_disks"] else None))
        except SystemExit as exc:  # no usable disk in the south half
            row.update(south_disks=0, label=None, best=None, confidence=None, disk_accuracy=None,
                       note=str(exc).splitlines()[-1][:200])
        row["enough_disks"] = bool(row["in_model"] and row["training_disks"] >= 2 and row["south_disks"] >= 2)
        row["right"] = row["label"] == name
        row["best_right"] = row["best"] == name
        rows.append(row)
    counted = [r for r in rows if r["enough_disks"]]
    return {"feature_set": feature_set, "classifier": classifier, "radius": radius,
            "unknown_threshold": (md.get("calibration") or {}).get("terrain_threshold", md.get("unknown_threshold")),
            "rows": rows,
            "regions_counted": len(counted), "right": sum(r["right"] for r in counted),
            "best_right": sum(r["best_right"] for r in counted),
            "mean_disk_accuracy": (sum(r["disk_accuracy"] for r in counted) / len(counted)) if counted else None,
            "timings_s": {"features": t_features, "train": t_train, "train_cpu": c_train}, "load_after_train": load_train,
            "load_after": list(os.getloadavg())}


def markdown(results: list[dict]) -> str:
    lines = ["# North half trained, south half classified (shared DEMs)", "",
             "Protocol (`benchmarks/classification_halves.py`, through the CLI only): each DEM's north half and south "
             "half written as GeoTIFFs; `orokit features north/*.tif`, `orokit train --drop-small-classes`, "
             "`orokit classify` on each south half. A region counts with >= 2 training disks and >= 2 south disks. "
             "Nothing was tuned on the south halves.", ""]
    for r in results:
        lines += [f"## features `{r['feature_set']}`, classifier `{r['classifier']}`, R = {r['radius']}", "",
                  f"**{r['right']} of {r['regions_counted']}** regions right (best class right: {r['best_right']} of "
                  f"{r['regions_counted']}; 'unknown' threshold {r['unknown_threshold']:.2f}); mean share of south "
                  f"disks right {100 * (r['mean_disk_accuracy'] or 0):.1f} %; features {r['timings_s']['features']:.1f} "
                  f"s, training {r['timings_s']['train']:.1f} s wall / {r['timings_s']['train_cpu']:.1f} s CPU "
                  f"(load average after training: {', '.join(f'{v:.1f}' for v in r['load_after_train'])}; at the "
                  f"end: {', '.join(f'{v:.1f}' for v in r['load_after'])}).", "",
                  "| region | training disks | south disks | answer | best class | mean calibrated prob. | south disks right |",
                  "|---|---:|---:|---|---|---:|---:|"]
        for row in r["rows"]:
            conf = f"{row['confidence']:.2f}" if row.get("confidence") is not None else "-"
            da = f"{100 * row['disk_accuracy']:.0f} %" if row.get("disk_accuracy") is not None else "-"
            mark = "" if not row["enough_disks"] else (" ✓" if row["right"] else " ✗")
            lines.append(f"| {row['region']}{'' if row['enough_disks'] else ' (not counted)'} | "
                         f"{row['training_disks']} | {row['south_disks']} | {row['label']}{mark} | {row['best']} | "
                         f"{conf} | {da} |")
        lines.append("")
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--features", nargs="+", default=["terrain", "orometry", "paper"])
    ap.add_argument("--classifier", default=None, help="default: the train command's default")
    ap.add_argument("--radius", default="10km")
    ap.add_argument("--out", type=Path, default=ROOT / "reports" / "classification" / "halves.md")
    a = ap.parse_args()
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from _record import record

    from orokit.io.atomic import write_text_atomic

    results = []
    with tempfile.TemporaryDirectory(prefix="orokit-halves-") as tmp:
        folder = Path(tmp)
        names = write_halves(folder)
        for fs in a.features:
            clf = a.classifier or ("rf" if fs == "paper" else _default_classifier())
            results.append(protocol(folder, names, feature_set=fs, classifier=clf, radius=a.radius))
            r = results[-1]
            print(f"{fs}/{clf}: {r['right']} of {r['regions_counted']} right (best {r['best_right']}), "
                  f"mean south-disk accuracy {100 * (r['mean_disk_accuracy'] or 0):.1f} %", flush=True)
    write_text_atomic(a.out, markdown(results))
    record("classification_halves", {"runs": results})


def _default_classifier() -> str:
    from orokit.cli.train import train

    return next(p.default for p in train.params if p.name == "classifier")


if __name__ == "__main__":
    main()
