"""``orokit synthesize``: a Divide Tree from a terrain type and its terrain, in one go."""
from __future__ import annotations

from pathlib import Path

import click

from orokit.cli.generator_options import generator_options
from orokit.cli.options import (
    INPUT,
    LENGTH,
    SIZE,
    InputSource,
    cell_size_option,
    center_option,
    output_frame,
    overwrite_option,
    progress_option,
    seed_option,
)
from orokit.cli.render import like_dem

#: files written into OUT besides those of ``orokit synthesize-tree``; hillshade.png is
#: written last and marks a complete folder
TERRAIN_FILES = ("dem.tif", "hillshade.png")
#: the completion marker: removed first on --overwrite, written last
MARKER = "hillshade.png"
#: outputs of later steps that describe the old terrain, removed on --overwrite
STALE_FILES = ("validation.json",)


def like_domain(like: InputSource, *, cell_size_m: float | None = None) -> tuple[float, float, float]:
    """Width, height and cell size (metres) of a DEM file or of a manifest dataset."""
    x0, y0, w, h, res, _ = like_box(like, cell_size_m=cell_size_m)
    return w, h, res


def texture_params(ttype) -> dict:
    """RenderParams keywords for the texture a terrain type recorded (none: {})."""
    t = ttype.texture
    if not t:
        return {}
    return {"texture_rms_m": float(t["rms_m"]), "texture_beta": float(t["beta"]),
            "texture_largest_m": float(t.get("largest_m", 1000.0))}


def like_box(like: str | InputSource, *, cell_size_m: float | None = None):
    """South-west corner, width, height, cell size (metres) and CRS (None: local grid) of a
    ``--like`` DEM, so a twin lands on the DEM's own grid."""
    dem = like_dem(like, cell_size_m=cell_size_m)
    t = dem.rio.transform()
    ny, nx = dem.shape
    xs, ys = (t.c, t.c + t.a * nx), (t.f, t.f + t.e * ny)
    crs = None if dem.attrs.get("local_grid") else dem.rio.crs
    return min(xs), min(ys), nx * abs(float(t.a)), ny * abs(float(t.e)), abs(float(t.a)), crs


def _like_dem(like: str | InputSource, *, cell_size_m: float | None = None):
    """The DEM named by --like (a file or a manifest dataset), in metres (see :func:`like_dem`)."""
    return like_dem(like, cell_size_m=cell_size_m)


@click.command(name="synthesize")
@click.option("--type", "type_file", required=True, type=click.Path(exists=True, dir_okay=False, path_type=Path),
              help="Terrain type JSON (from `orokit type`).")
@click.option("--size", type=SIZE, default="90km", show_default=True,
              help="Domain size: 90km, 90000m, 90x60km (a plain number is metres).")
@click.option("--resolution", type=LENGTH, default=None,
              help="Cell size of the raster (30m; a plain number is metres) [default: 30m, or that of --like].")
@click.option("--like", type=INPUT, default=None,
              help="A DEM file or a dataset name of the manifest: the domain gets its size (and cell size unless "
                   "--resolution is given), e.g. a synthetic twin of a real DEM.")
@cell_size_option(help="Cell size of a --like file without georeference")
@click.option("--n-peaks", type=int, default=None, help="Number of peaks (default: type density x area).")
@click.option("--control-elevation", default=None,
              help="Coarse elevation map C_H (m) guiding where high and low peaks go: a raster file, or 'like' for "
                   "the --like DEM itself (a twin then keeps the real large-scale relief).")
@click.option("--erosion/--no-erosion", default=True, show_default=True, help="Multi-scale constrained erosion.")
@seed_option(what="the tree and the raster", default=None, recorded_in="synthesis.json and the dem.tif tags")
@click.option("--crs", default=None,
              help="Output CRS (projected EPSG/WKT), or 'local' for a local metric frame with the south-west corner at "
                   "(0, 0) [default: the --like DEM's grid and CRS, else a local azimuthal-equidistant CRS centred "
                   "where the type was measured, else a local frame].")
@center_option()
@click.option("--tin", "write_tin", is_flag=True, help="Also write the TIN as tin.ply.")
@click.option("-o", "--output", "outdir", required=True, type=click.Path(file_okay=False, path_type=Path),
              help="Output folder: dividetree.gpkg/.txt, peaks.csv, synthesis.json, dem.tif, hillshade.png.")
@overwrite_option("existing outputs in OUTPUT")
@progress_option()
@generator_options
def synthesize(type_file, size, resolution, like, cell_size_m, n_peaks, control_elevation, erosion, seed, crs, center,
               write_tin,
               outdir, overwrite, progress, generator, params, exemplar) -> None:
    """Synthesize a Divide Tree following a terrain type and render it to a raster.

    OUTPUT is locked for the whole run. The new files are written into a hidden folder
    beside OUTPUT and moved in only when all are complete (hillshade.png, the marker of a
    complete folder, last), so an interrupted or failed run (disk full) keeps the previous
    outputs unchanged and never leaves old and new files side by side.
    """
    import json
    import time

    import numpy as np

    from orokit.cli.render import write_outputs
    from orokit.raster.params import RenderParams
    from orokit.raster.rasterize import make_grid
    from orokit.raster.render import render_elevation, resolve_seed
    from orokit.raster.skeleton import tree_extent
    from orokit.synthesis.fidelity import compare_to_type
    from orokit.io.synthesis_io import SYNTHESIS_FILES, write_synthesis
    from orokit.synthesis.terrain_type import load_terrain_type
    from orokit.synthesis.tree import synthesize_divide_tree

    from orokit.cli.outputs import claim_outputs

    outputs = (MARKER,) + tuple(f for f in SYNTHESIS_FILES + TERRAIN_FILES + ("tin.ply",) if f != MARKER)
    stage = claim_outputs(outdir, names=outputs + STALE_FILES)  # locked for the whole run
    existing = [f for f in outputs if (outdir / f).exists()]
    if existing and not overwrite:
        raise click.UsageError(f"{outdir} already holds {', '.join(existing)}; pass --overwrite to replace them")
    center_ll: tuple[float, float] | None = center
    crs, local = output_frame(crs, center_ll)
    like_origin = None
    if like is not None:
        x0, y0, w, h, like_res, like_crs = like_box(like, cell_size_m=cell_size_m)
        res = resolution if resolution is not None else like_res
        if crs is None and center_ll is None and not local:
            like_origin = (x0, y0, like_crs)  # the twin lands on the DEM's grid, in its CRS
    else:
        w, h = size
        res = resolution if resolution is not None else 30.0
    make_grid((0.0, 0.0, w, h), res)  # resolution errors before the synthesis
    parsed = None
    if generator != "argudo" or params:
        from orokit.cli.generator_options import check_generator_inputs

        if write_tin:
            raise click.UsageError("--tin needs --generator argudo (other generators build no TIN)")
        if generator == "argudo":
            params = (f"erosion={erosion}",) + tuple(params)
        parsed = check_generator_inputs(generator, params, exemplar)
    ttype = load_terrain_type(type_file)
    if like_origin is None and center_ll is None and not local:
        # the terrain goes where its type was measured (a local azimuthal-equidistant CRS centred
        # there, or the given --crs centred there), not to a CRS's false origin
        center_ll = ttype.source_center
    if seed is None:
        seed = resolve_seed(None)  # fresh entropy, recorded, so the run can be replayed
    from orokit.cli.progress import StageProgress

    bar = StageProgress("synthesize", ["synthesize tree", "render", "write"], enabled=progress)
    t0 = time.perf_counter()
    # the same int seeds the tree and the raster: `synthesize-tree --seed S` gives this tree and
    # `render --seed S` this raster
    c_h = control_elevation
    if control_elevation == "like":
        if like is None:
            raise click.UsageError("--control-elevation like needs --like")
        c_h = np.asarray(like_dem(like, cell_size_m=cell_size_m).values, dtype=float)  # row 0 north, stretched
    elif control_elevation is not None and not Path(control_elevation).exists():
        raise click.BadParameter(f"{control_elevation} does not exist", param_hint="--control-elevation")
    if like_origin is not None:
        from orokit.synthesis.controls import Domain, make_domain

        shape = make_domain((w, h)).shape
        domain = Domain(like_origin[0], like_origin[1], w, h, like_origin[2], shape)
        tree = synthesize_divide_tree(ttype, domain=domain, n_peaks=n_peaks, control_elevation=c_h, rng=seed)
    else:
        tree = synthesize_divide_tree(ttype, size_m=(w, h), n_peaks=n_peaks, crs=crs, center=center_ll,
                                      control_elevation=c_h, rng=seed)
    bar.advance()
    if parsed is None:
        dem, skel = render_elevation(tree, cell_size_m=res, extent=tree_extent(tree), erosion=erosion,
                                     params=RenderParams(min_prominence_m=float(tree.attrs.get("min_prominence_m", 30.0)),
                                                         **texture_params(ttype)),
                                     return_skeleton=True, rng=seed)
    else:
        from orokit.cli.generator_options import render_generator

        skel = None
        dem = render_generator(tree, generator=generator, params=parsed, cell_size_m=res, extent=tree_extent(tree),
                               seed=seed, exemplar=exemplar)
    bar.advance()
    # the new files go to a hidden folder beside OUTPUT and replace the old ones only when all
    # are written (the marker first removed, moved in last; the old ones not rewritten removed)
    new = stage.folder(outdir, marker=MARKER, stale=outputs + STALE_FILES)
    extra = {"seed": seed, "types": [str(type_file)], "cell_size_m": res, "erosion": bool(erosion),
             "like": None if like is None else str(like),
             "generator": generator, "generator_parameters": json.loads(dem.attrs.get("parameters", "{}")),
             "control_elevation": None if control_elevation is None else str(control_elevation),
             "render_timings_s": json.loads(dem.attrs.get("timings", "{}")),
             "fidelity": compare_to_type(tree, ttype).reset_index().to_dict(orient="records")}
    from orokit.synthesis.tree import peaks_table

    write_synthesis(tree, new, peaks=peaks_table(tree), extra=extra)
    write_outputs(dem, new / "dem.tif", preview=new / "hillshade.png",
                  tin_path=new / "tin.ply" if write_tin else None, skeleton=skel)
    stage.commit()
    bar.advance()
    bar.close()
    click.echo(f"{tree.n_peaks} peaks, {dem.shape[1]} x {dem.shape[0]} cells at {res:g} m "
               f"in {time.perf_counter() - t0:.1f} s -> {outdir}")
