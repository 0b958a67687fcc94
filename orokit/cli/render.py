"""``orokit render``: an elevation raster (COG) from a Divide Tree."""
from __future__ import annotations

from pathlib import Path

import click

from orokit.cli.generator_options import generator_options
from orokit.cli.options import (
    INPUT,
    LENGTH,
    InputSource,
    cell_size_option,
    resolve_input,
    min_prominence_option,
    overwrite_option,
    progress_option,
    refuse_existing,
    seed_option,
)


def read_tree(path: Path, *, cell_size_m: float | None = None):
    """A Divide Tree from .gpkg, reference .txt, or a folder holding dividetree.gpkg."""
    from orokit.io.divide_tree_io import read_divide_tree

    return read_divide_tree(path, cell_size_m=cell_size_m)


def like_dem(like: str | Path | InputSource, *, cell_size_m: float | None = None, z_units: str | None = "m",
             hint: str = "--like"):
    """The DEM named by ``--like``: a raster file or a manifest dataset name (metres).

    A file is read with ``z_units`` (``"m"`` when only its grid matters; ``None`` to use
    the units it declares) and ``cell_size_m`` for rasters without georeferencing; a
    dataset comes with the manifest's units and cell size (:func:`orokit.cli.options.resolve_input`).
    """
    src = like if isinstance(like, InputSource) else resolve_input(like, hint=hint)
    dem = src.read_dem() if src.dataset else src.read_dem(z_units=z_units, cell_size_m=cell_size_m)
    if dem.rio.crs is not None and dem.rio.crs.is_geographic:
        raise click.BadParameter(f"{like} is in a geographic CRS; give --size and --resolution in metres",
                                 param_hint=hint)
    if dem.rio.crs is not None and not dem.attrs.get("local_grid"):  # its grid is taken in metres
        from orokit.errors import CRSError
        from orokit.geodesy import metric_crs

        try:
            metric_crs(dem.rio.crs, str(like))
        except CRSError as exc:
            raise click.BadParameter(str(exc), param_hint=hint) from exc
    return dem


def like_grid(like: str | Path | InputSource, *, cell_size_m: float | None = None
              ) -> tuple[tuple[float, float, float, float], float]:
    """Extent ``(xmin, ymin, xmax, ymax)`` and cell size (m) of a ``--like`` raster or dataset."""
    dem = like_dem(like, cell_size_m=cell_size_m)
    t = dem.rio.transform()
    ny, nx = dem.shape
    xs = (t.c, t.c + t.a * nx)
    ys = (t.f, t.f + t.e * ny)
    if abs(abs(t.a) - abs(t.e)) > 1e-6 * abs(t.a):
        raise click.BadParameter(f"{like} has non-square cells ({abs(t.a):g} x {abs(t.e):g}); give --resolution "
                                 "and --extent", param_hint="--like")
    return (min(xs), min(ys), max(xs), max(ys)), abs(float(t.a))


def write_outputs(dem, out: Path, *, preview: Path | None, tin_path: Path | None, skeleton=None,
                  name: str | None = None) -> None:
    """Write the raster, then the TIN, then the hillshade preview (each atomically; the
    preview last, so it marks a complete set). ``name``: the raster's name in messages (``out``
    may be a staged temporary file)."""
    from orokit.cli.generator_options import EXTRA_TAGS
    from orokit.io.atomic import check_free_space
    from orokit.io.raster_io import write_cog, write_hillshade_png, write_tin_ply

    # float32 cells + overviews + the COG driver's temporary copy (about a third)
    check_free_space(out, dem.size * 4 * 1.7, what=f"{name or Path(out).name} ({dem.shape[1]} x {dem.shape[0]} cells)")
    write_cog(dem, out, tags={k: v for k, v in dem.attrs.items() if k in EXTRA_TAGS})
    if tin_path is not None and skeleton is not None:
        write_tin_ply(skeleton.tin, tin_path)
    if preview is not None:
        write_hillshade_png(dem, preview)


@click.command(name="render")
@click.argument("tree", type=click.Path(exists=True, path_type=Path))
@click.option("-o", "--output", "out", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="Output GeoTIFF (COG).")
@click.option("--resolution", type=LENGTH, default=None,
              help="Cell size: 30m, 0.03km (a plain number is metres) [default: that of --like, else 30m].")
@click.option("--erosion/--no-erosion", default=True, show_default=True, help="Multi-scale constrained erosion.")
@seed_option(what="the raster", default=None, recorded_in="the GeoTIFF tags")
@click.option("--extent", type=(float, float, float, float), default=None,
              help="XMIN YMIN XMAX YMAX in the tree's CRS (default: the tree's domain or bounding box).")
@click.option("--like", type=INPUT, default=None,
              help="Raster file or manifest dataset (e.g. the DEM the tree came from): its extent and cell size.")
@min_prominence_option(help="Prominence threshold eps: the added noise stays below it", zero_keeps_all=False)
@click.option("--lambda", "lam", type=LENGTH, default="200m", show_default=True, help="Meshing distance lambda.")
@cell_size_option(help="Cell size of a reference .txt tree or of a --like raster without georeference")
@click.option("--preview", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Also write a hillshade PNG.")
@click.option("--tin", "tin_path", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Also write the TIN as a PLY mesh.")
@overwrite_option("existing outputs")
@progress_option()
@generator_options
def render(tree, out, resolution, erosion, seed, extent, like, min_prominence_m, lam, cell_size_m, preview,
           tin_path, overwrite, progress, generator, params, exemplar) -> None:
    """Render the Divide Tree TREE (.gpkg, .txt or a synthesize folder) to an elevation raster.

    --generator picks the backend (default argudo, orokit's renderer); --erosion, --lambda and
    --min-prominence are the argudo parameters, other backends take --param K=V.
    """
    import gc
    import time

    from orokit.cli.main import owns_process

    # in orokit's own process, no garbage collection while the modules load and the tree is read, then
    # the objects alive by then (the modules', ~150 k) are frozen out of the render's full collections:
    # ~0.5 CPU s of collections on the main thread (measured, session 13), the same outputs (an error
    # before loaded() ends the process)
    paused = owns_process() and gc.isenabled()
    if paused:
        gc.disable()

    def loaded() -> None:
        if paused and not gc.isenabled():
            gc.freeze()
            gc.enable()

    from orokit.cli.outputs import claim_outputs
    from orokit.cli.progress import StageProgress
    from orokit.raster.params import RenderParams
    from orokit.raster.render import render_elevation

    stage = claim_outputs(out, preview, tin_path)  # locked for the whole run
    refuse_existing(out, preview, tin_path, overwrite=overwrite)
    if like is not None:
        if extent is not None:
            raise click.UsageError("give --extent or --like, not both")
        extent, like_res = like_grid(like, cell_size_m=cell_size_m)
    res = resolution if resolution is not None else (like_res if like is not None else 30.0)
    if generator != "argudo" or params:
        from orokit.cli.generator_options import check_generator_inputs, render_generator

        if tin_path is not None:
            raise click.UsageError("--tin needs --generator argudo (other generators build no TIN)")
        if generator == "argudo":
            params = (f"lam={lam}", f"min_prominence_m={min_prominence_m}", f"erosion={erosion}") + tuple(params)
        parsed = check_generator_inputs(generator, params, exemplar)
        with StageProgress("render", ["read tree", f"render ({generator})", "write"], enabled=progress) as bar:
            t = read_tree(tree, cell_size_m=cell_size_m)
            loaded()
            bar.advance()
            t0 = time.perf_counter()
            dem = render_generator(t, generator=generator, params=parsed, cell_size_m=res, extent=extent, seed=seed,
                                   tree_path=tree, exemplar=exemplar)
            bar.advance()
            write_outputs(dem, out, preview=preview, tin_path=None)
            bar.advance()
        click.echo(f"{dem.shape[1]} x {dem.shape[0]} cells at {res:g} m from {t.n_peaks} peaks with {generator} "
                   f"in {time.perf_counter() - t0:.1f} s (seed {dem.attrs['seed']}) -> {out}")
        return
    params = RenderParams(lam=lam, min_prominence_m=min_prominence_m)
    with StageProgress("render", ["read tree", "render" + (" + erosion" if erosion else ""), "write"],
                       enabled=progress) as bar:
        t = read_tree(tree, cell_size_m=cell_size_m)
        loaded()
        bar.advance()
        t0 = time.perf_counter()
        dem, skel = render_elevation(t, cell_size_m=res, extent=extent, erosion=erosion, params=params,
                                     return_skeleton=True, rng=seed)
        bar.advance()
        # staged: the old outputs are replaced only once every new one is written
        write_outputs(dem, stage.file(out), preview=None if preview is None else stage.file(preview),
                      tin_path=None if tin_path is None else stage.file(tin_path), skeleton=skel, name=out.name)
        stage.commit()
        bar.advance()
    click.echo(f"{dem.shape[1]} x {dem.shape[0]} cells at {res:g} m from {t.n_peaks} peaks "
               f"in {time.perf_counter() - t0:.1f} s (seed {dem.attrs['seed']}) -> {out}")
