"""``orokit synthesize-tree``: a new Divide Tree following one or several terrain types."""
from __future__ import annotations

from pathlib import Path

import click

from orokit.cli.options import (
    LENGTH,
    SIZE,
    center_option,
    output_frame,
    overwrite_option,
    parse_length,
    progress_option,
    seed_option,
)


def parse_size(text: str) -> tuple[float, float]:
    """'90km', '90000', '90000m', '90x60km' -> (width, height) in metres (strict, see
    :func:`orokit.cli.options.parse_length`)."""
    return parse_length(text, allow_bare=True, pair=True, hint="--size")


@click.command(name="synthesize-tree")
@click.option("--type", "type_files", required=True, multiple=True,
              type=click.Path(exists=True, dir_okay=False, path_type=Path),
              help="Terrain type JSON (from `orokit type`); repeat with --type-map to mix types (map value i = "
                   "i-th --type).")
@click.option("--size", "size", type=SIZE, default="90km", show_default=True,
              help="Domain size: 90km, 90000m, 90x60km (a plain number is metres).")
@click.option("--n-peaks", type=int, default=None, help="Number of peaks (default: type density x area).")
@click.option("--control-elevation", type=click.Path(exists=True, path_type=Path), default=None,
              help="Coarse elevation map C_H in metres (any CRS; resampled).")
@click.option("--control-density", type=click.Path(exists=True, path_type=Path), default=None,
              help="Peak density map C_P >= 0 (0 = no peaks: sea, lakes).")
@click.option("--type-map", type=click.Path(exists=True, path_type=Path), default=None,
              help="Raster of type indices 0..k-1 into the --type list.")
@click.option("--peaks", "fixed_peaks", type=click.Path(exists=True, path_type=Path), default=None,
              help="Fixed user peaks (GeoPackage/GeoParquet/CSV with x, y or point geometry, and elevation in m).")
@click.option("--fragment", type=click.Path(exists=True, path_type=Path), default=None,
              help="Divide Tree fragment (.gpkg from orokit, or reference .txt) to keep and complete around.")
@click.option("--fragment-offset", type=(float, float), default=(0.0, 0.0), show_default=True,
              help="Shift (metres) applied to the fragment.")
@click.option("--crs", default=None,
              help="Output CRS (EPSG:xxxx or WKT; projected), or 'local' for a local metric frame. Default: a local "
                   "azimuthal-equidistant CRS centred where the (first) type was measured, else a local frame.")
@center_option()
@seed_option(what="the tree", default=None, recorded_in="synthesis.json")
@click.option("--txt-cell-size", type=LENGTH, default="30m", show_default=True,
              help="Virtual cell size of the pixel coordinates in dividetree.txt (a plain number is metres).")
@click.option("-o", "--output", "outdir", required=True, type=click.Path(file_okay=False, path_type=Path),
              help="Output folder: dividetree.gpkg, dividetree.txt, peaks.csv, synthesis.json.")
@overwrite_option("existing outputs in OUTPUT")
@progress_option()
def synthesize_tree(type_files, size, n_peaks, control_elevation, control_density, type_map, fixed_peaks, fragment,
                    fragment_offset, crs, center, seed, txt_cell_size, outdir, overwrite, progress) -> None:
    """Synthesize a Divide Tree that follows the orometry of the given terrain type(s)."""
    import time

    from orokit.synthesis.fidelity import compare_to_type
    from orokit.io.synthesis_io import SYNTHESIS_FILES, write_synthesis
    from orokit.synthesis.terrain_type import load_terrain_type
    from orokit.synthesis.tree import synthesize_divide_tree

    from orokit.cli.outputs import claim_outputs

    claim_outputs(outdir, names=SYNTHESIS_FILES)  # locked for the whole run
    existing = [f for f in SYNTHESIS_FILES if (outdir / f).exists()]
    if existing and not overwrite:
        raise click.UsageError(f"{outdir} already holds {', '.join(existing)}; pass --overwrite to replace them")
    if type_map is None and len(type_files) > 1:
        raise click.BadParameter("several --type need a --type-map telling where each applies", param_hint="--type")
    w, h = size
    if seed is None:
        from orokit.raster.render import resolve_seed

        seed = resolve_seed(None)  # fresh entropy, recorded in synthesis.json, so the run can be replayed
    types = [load_terrain_type(p) for p in type_files]
    crs, local = output_frame(crs, center)
    if not local and center is None:
        center = types[0].source_center  # where the type was measured (None: a local frame)
    fixed = _read_points(fixed_peaks) if fixed_peaks is not None else None
    frag = _read_tree(fragment) if fragment is not None else None
    from orokit.cli.progress import StageProgress

    bar = StageProgress("synthesize-tree", ["synthesize tree", "write"], enabled=progress)
    t0 = time.perf_counter()
    tree = synthesize_divide_tree(
        types if len(types) > 1 else types[0], size_m=(w, h), n_peaks=n_peaks, crs=crs, center=center,
        control_elevation=None if control_elevation is None else str(control_elevation),
        control_density=None if control_density is None else str(control_density),
        type_map=None if type_map is None else str(type_map), fixed_peaks=fixed, fragment=frag,
        fragment_offset=fragment_offset, rng=seed,
    )
    bar.advance()
    extra = {"seed": seed, "types": [str(p) for p in type_files]}
    if len(types) == 1:
        extra["fidelity"] = compare_to_type(tree, types[0]).reset_index().to_dict(orient="records")
    from orokit.synthesis.tree import peaks_table

    write_synthesis(tree, outdir, peaks=peaks_table(tree), txt_cell_m=txt_cell_size, extra=extra)
    bar.advance()
    bar.close()
    click.echo(f"{tree.n_peaks} peaks, {len(tree.edges)} ridges in {time.perf_counter() - t0:.2f} s "
               f"(OT rounds {tree.attrs['ot_iterations']}) -> {outdir}")


def _read_points(path: Path):
    frame = _read_points_file(path)
    frame.attrs["source"] = str(path)  # errors about fixed peaks name the file
    return frame


def _read_points_file(path: Path):
    import pandas as pd

    if path.suffix.lower() == ".csv":
        return pd.read_csv(path)
    import geopandas as gpd

    if path.suffix.lower() == ".parquet":
        return gpd.read_parquet(path)
    return gpd.read_file(path, layer="peaks") if _has_layer(path, "peaks") else gpd.read_file(path)


def _has_layer(path: Path, name: str) -> bool:
    try:
        import pyogrio

        return name in [row[0] for row in pyogrio.list_layers(path)]
    except Exception:  # noqa: BLE001 - not a multi-layer source
        return False


def _read_tree(path: Path):
    from orokit.io.divide_tree_io import read_divide_tree

    return read_divide_tree(path)
