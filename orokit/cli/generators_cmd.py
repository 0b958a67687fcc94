"""``orokit generators-run`` and ``orokit generators-report``: the generator ranking table."""
from __future__ import annotations

import json
from pathlib import Path

import click

from orokit.cli.options import LENGTH, min_prominence_option, overwrite_option, seed_option


def _real_dem(like: str):
    from orokit.cli.render import like_dem

    return like_dem(like)


@click.command(name="generators-run")
@click.option("--tree", "tree_dir", required=True, type=click.Path(exists=True, path_type=Path),
              help="Divide Tree shared by all generators (a synthesize-tree folder or .gpkg).")
@click.option("--type", "type_file", required=True, type=click.Path(exists=True, dir_okay=False, path_type=Path),
              help="Terrain type the tree follows (histogram errors).")
@click.option("--like", required=True, help="The real DEM (file or manifest dataset): cell size and landforms.")
@click.option("--generator", required=True, help="Generator name (see `orokit render --list-generators`).")
@click.option("--param", "params", multiple=True, metavar="K=V", help="Generator parameter (repeatable).")
@click.option("--exemplar", default=None,
              help="Exemplar DEM (file or dataset) for generators that learn from one [default: the --like DEM].")
@click.option("--label", default=None,
              help="Row name in the ranking [default: the generator], e.g. guerin-cross for another exemplar.")
@seed_option(what="the render", required=True)
@click.option("--model", "model_path", type=click.Path(exists=True, dir_okay=False, path_type=Path), default=None,
              help="Region model (.skops) for the reclassification.")
@min_prominence_option(help="Prominence threshold eps of the re-analysis")
@click.option("-o", "--output", "out", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="result.json; dem.tif and hillshade.png are written beside it.")
@overwrite_option("an existing result")
def generators_run(tree_dir, type_file, like, generator, params, exemplar, label, seed, model_path, min_prominence_m,
                   out, overwrite) -> None:
    """One ranking run: render TREE with GENERATOR in its own process, then measure it.

    The render runs as a child `orokit render` process (its wall time and peak RSS are
    recorded); then the raster is re-analysed (tree peaks recovered, extra peaks, histogram
    errors against the type), reclassified with the model, and its landforms compared with
    the real DEM. A failed render or measure is recorded in result.json (``failed``), not
    dropped, and the command still exits 0 so the table shows it.
    """
    import os
    import resource
    import subprocess
    import sys
    import time

    from orokit.io.atomic import write_text_atomic

    if out.exists() and not overwrite:
        raise click.UsageError(f"{out} exists; pass --overwrite to replace it")
    from orokit.generators import get_generator

    spec = get_generator(generator)  # unknown names fail here, before anything runs
    if exemplar is None and "exemplar" in spec.inputs:
        exemplar = like
    out.parent.mkdir(parents=True, exist_ok=True)
    dem_path = out.parent / "dem.tif"
    hs_path = out.parent / "hillshade.png"
    real = _real_dem(like)
    res = abs(float(real.rio.transform().a))
    from orokit.cli.render import read_tree
    from orokit.raster.skeleton import tree_extent

    tree = read_tree(tree_dir)
    ext = tree_extent(tree)
    result: dict = {"generator": label or generator, "backend": generator, "region": like, "seed": seed, "exemplar": exemplar, "params": list(params), "tree": str(tree_dir), "failed": False,
                    "load_average_before": list(os.getloadavg())}
    cmd = [sys.executable, "-m", "orokit.cli.main", "-q", "render",
           str(tree_dir), "-o", str(dem_path), "--resolution", f"{res}m", "--extent", *(str(v) for v in ext),
           "--generator", generator, "--seed", str(seed), "--preview", str(hs_path), "--overwrite"]
    for p in params:
        cmd += ["--param", p]
    if exemplar is not None:
        cmd += ["--exemplar", str(exemplar)]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True)
    result["wall_s"] = round(time.perf_counter() - t0, 3)
    result["peak_rss_gb"] = round(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024**2, 3)
    if proc.returncode != 0:
        lines = (proc.stderr or proc.stdout or "").strip().splitlines()
        result.update({"failed": True, "stage": "render", "error": lines[-1] if lines else f"exit {proc.returncode}"})
    else:
        try:
            result.update(_measure(dem_path, tree, type_file, real, model_path, min_prominence_m, like))
        except Exception as exc:  # noqa: BLE001 - a failed measure is reported, not dropped
            result.update({"failed": True, "stage": "measure", "error": f"{type(exc).__name__}: {exc}"})
    write_text_atomic(out, json.dumps(result, indent=1, default=float))
    state = f"FAILED ({result['stage']}: {result['error']})" if result["failed"] else \
        f"recovered {100 * result['recovered_share']:.1f} %, extra {100 * result['extra_share']:.1f} %"
    click.echo(f"{generator} seed {seed} on {like}: {state} -> {out}")


def _measure(dem_path: Path, tree, type_file: Path, real, model_path: Path | None, min_prominence_m: float,
             label: str) -> dict:
    from orokit.io.dem import read_dem
    from orokit.synthesis.terrain_type import load_terrain_type
    from orokit.validate.landform import compare_landforms
    from orokit.validate.roundtrip import roundtrip

    import rasterio

    dem = read_dem(str(dem_path))
    with rasterio.open(dem_path) as src:
        tags = src.tags()
    ttype = load_terrain_type(type_file)
    model = None
    if model_path is not None:
        from orokit.classify.model import load_model

        model = load_model(model_path)
    rt = roundtrip(dem, tree, min_prominence_m=min_prominence_m, terrain_type=ttype, model=model, expected_label=label)
    s = rt.summary()
    r = {k: s[k] for k in ("tree_peaks", "recovered_share", "extra_peaks", "extra_share", "raster_peaks")}
    for k in ("predicted", "n_disks", "disk_accuracy", "vote_correct"):
        if k in s:
            r[k] = s[k]
    hist = rt.histograms
    assert hist is not None  # the round trip was given the terrain type
    for feat in ("elevation", "prominence", "dominance", "isolation_distance"):
        r[f"max_bin_error_{feat}"] = float(hist.loc[feat, "max_bin_error"])
    lf = compare_landforms(real, dem)
    r["landform"] = {k: float(v) for k, v in lf["distance"].items()}
    r["landform_target"] = {k: float(v) for k, v in lf["target"].items()}
    r["landform_ok"] = int(lf["ok"].sum())
    r["landform_n"] = int(len(lf))
    r["render_s"] = round(sum(json.loads(tags.get("timings", "{}")).values()), 3)
    r["shape"] = f"{dem.shape[1]}x{dem.shape[0]}"
    r["real_shape"] = f"{real.shape[1]}x{real.shape[0]}"
    r["parameters"] = json.loads(tags.get("parameters", "{}"))
    if "derived" in tags:  # parameter values the backend set from its inputs (e.g. the exemplar)
        r["derived"] = json.loads(tags["derived"])
    return r


@click.command(name="generators-report")
@click.argument("results", nargs=-1, required=True, type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("-o", "--output", "out", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="README.md of the ranking (README.csv and <region>.png hillshades beside it).")
@click.option("--note", default=None, help="A paragraph added under the introduction (e.g. how the runs differ).")
@overwrite_option("existing outputs")
def generators_report(results, out, note, overwrite) -> None:
    """Rank the generators from the result.json files of `orokit generators-run`."""
    from orokit.reports.generators import write_ranking_report

    if out.exists() and not overwrite:
        raise click.UsageError(f"{out} exists; pass --overwrite to replace it")
    runs = []
    for p in results:
        r = json.loads(Path(p).read_text())
        r["hillshade"] = str(Path(p).parent / "hillshade.png")
        runs.append(r)
    reals = {}
    for region in sorted({r["region"] for r in runs}):
        try:
            reals[region] = _real_dem(region)
        except click.BadParameter:
            reals[region] = None
    write_ranking_report(runs, reals, out, note=note)
    click.echo(f"{len(runs)} runs ({sum(r['failed'] for r in runs)} failed) -> {out}")
