"""``orokit type``: a terrain type (orometric statistics) from an analysis, a DEM or a Divide Tree."""
from __future__ import annotations

from pathlib import Path

import click

from orokit.cli.options import (
    INPUT,
    InputSource,
    cell_size_option,
    min_prominence_option,
    overwrite_option,
    progress_option,
    refuse_existing,
    z_units_option,
)


@click.command(name="type")
@click.argument("src", metavar="SOURCE", type=INPUT)
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="Terrain type JSON to write.")
@click.option("--name", default=None, help="Type name (default: the input's name).")
@min_prominence_option(default=None, help="Prominence threshold eps [default: the analysis' threshold, else 30m]")
@z_units_option(help="Elevation units of a DEM or Divide Tree TXT input (PNG DEMs and TXT trees: ft).")
@cell_size_option(help="Cell size of a PNG DEM or a Divide Tree TXT")
@click.option("--isolation-basis", type=click.Choice(["peaks", "terrain"]), default="peaks", show_default=True,
              help="Isolation to the nearest higher peak (comparable with synthesized trees) or to the "
                   "nearest higher terrain cell (analysis column).")
@click.option("--rho", type=float, default=None, help="Ridge exponent (default: estimated from the Divide Tree).")
@click.option("--scale-prominence", type=float, default=None, help="Edit: multiply prominences by this factor.")
@click.option("--scale-elevation", type=float, default=None, help="Edit: multiply elevations by this factor.")
@click.option("--shift-elevation", type=float, default=None, help="Edit: add this many metres to elevations.")
@click.option("--density", type=float, default=None, help="Edit: peak density in peaks per km2.")
@click.option("--area-km2", type=float, default=None,
              help="Area of a Divide Tree input in km2 (default: extent of its peaks, saddles and runoffs).")
@overwrite_option("an existing OUTPUT")
@progress_option()
def type_cmd(src: InputSource, output: Path, name: str | None, min_prominence_m: float | None, z_units: str | None,
             cell_size_m: float | None, isolation_basis: str, rho: float | None, scale_prominence: float | None,
             scale_elevation: float | None, shift_elevation: float | None, density: float | None,
             area_km2: float | None, overwrite: bool, progress: bool) -> None:
    """Build the terrain type of SOURCE and write it as versioned JSON.

    SOURCE is an `orokit analyze` output folder, a DEM (analysed first; a DEM of the
    manifest by name, e.g. gobi), or a Divide
    Tree (reference .txt or .gpkg; its area is the extent of its peaks, saddles and
    runoffs unless --area-km2 is given).
    """
    from orokit.synthesis.terrain_type import TerrainType

    from orokit.cli.outputs import claim_outputs

    claim_outputs(output)  # locked for the whole run
    refuse_existing(output, overwrite=overwrite)
    source = src.path
    if source.is_dir():
        tt = TerrainType.from_analysis(source, min_prominence_m=min_prominence_m, name=name,
                                       isolation_basis=isolation_basis, rho=rho)
        dem = _analysed_dem(source)
        if dem is not None:
            tt = _with_texture(tt, dem)
    elif source.suffix.lower() in (".txt", ".gpkg"):
        from orokit.io.divide_tree_io import read_divide_tree

        tree = read_divide_tree(source, cell_size_m=cell_size_m, z_units=z_units or "ft")
        area = area_km2 if area_km2 is not None else _tree_area_km2(tree)
        eps = 30.0 if min_prominence_m is None else min_prominence_m
        tt = TerrainType.from_divide_tree(tree, area_km2=area, min_prominence_m=eps,
                                          name=name or source.stem, rho=rho,
                                          provenance={"source": str(source), "area_from": "tree extent"})
    else:
        from orokit.analysis import analyze

        da = src.read_dem(z_units=z_units, cell_size_m=cell_size_m)
        result = analyze(da, min_prominence_m=30.0 if min_prominence_m is None else min_prominence_m, progress=progress)
        tt = TerrainType.from_analysis(result, name=name or src.dataset or source.stem, isolation_basis=isolation_basis, rho=rho)
        tt = _with_texture(tt, da)
    if scale_prominence is not None:
        tt = tt.scaled("prominence", scale_prominence)
    if scale_elevation is not None:
        tt = tt.scaled("elevation", scale_elevation)
    if shift_elevation is not None:
        tt = tt.shifted("elevation", shift_elevation)
    if density is not None:
        tt = tt.with_density(density)
    tt.save(output)
    click.echo(f"terrain type {tt.name!r}: {tt.provenance.get('n_peaks')} peaks, "
               f"{tt.peak_density_per_km2:.4f} peaks/km2, rho={tt.rho:g} -> {output}")


def _tree_area_km2(tree) -> float:
    """Area covered by a Divide Tree read from a file: its raster extent or bounding box."""
    import pandas as pd

    parts = [tree.peaks[["x", "y"]], tree.saddles[["x", "y"]]]
    run = (tree.attrs or {}).get("runoffs")
    if isinstance(run, pd.DataFrame) and {"x", "y"} <= set(run.columns):
        parts.append(run[["x", "y"]])
    xy = pd.concat(parts)
    cell = float((tree.attrs or {}).get("cell_size_m") or 0.0)
    from orokit.geodesy import parse_crs

    crs = parse_crs(tree.crs)
    if crs is not None and crs.is_geographic:  # lon/lat box: its area on the ellipsoid
        from affine import Affine

        from orokit.sampling.grid import grid_area_km2

        w, h = float(xy["x"].max() - xy["x"].min()), float(xy["y"].max() - xy["y"].min())
        return grid_area_km2(Affine(w, 0.0, float(xy["x"].min()), 0.0, -h, float(xy["y"].max())), crs, (1, 1))
    from orokit.synthesis.orometry import planar_xy

    x, y = planar_xy(xy["x"].to_numpy(), xy["y"].to_numpy(), crs)  # metres (a CRS in feet converted)
    return float((x.max() - x.min() + cell) * (y.max() - y.min() + cell)) / 1e6


def _with_texture(tt, dem):
    """The type with the DEM's short-wavelength texture (what the renderer adds back)."""
    import numpy as np

    from orokit.raster.noise import texture_spectrum
    from orokit.raster.shade import row_cell_sizes_m

    dx, dy = row_cell_sizes_m(dem)
    rms, beta = texture_spectrum(np.asarray(dem.values), float(np.sqrt(np.mean(dx) * dy)))
    return tt.with_texture(rms, beta)


def _analysed_dem(folder: Path):
    """The DEM an ``orokit analyze`` folder was made from (its manifest dataset or source file), or None."""
    import json
    import logging

    log = logging.getLogger(__name__)
    try:
        attrs = json.loads((folder / "analysis.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    try:
        if attrs.get("dataset"):
            from orokit.data import open_dataset_dem

            return open_dataset_dem(str(attrs["dataset"]))
        src = attrs.get("source")
        if src and Path(src).is_file():
            from orokit.io.dem import read_dem

            return read_dem(src, z_units=attrs.get("z_units_in") or "m")
    except Exception as exc:  # noqa: BLE001 - the texture is optional; the type is still valid without it
        log.warning("no texture for the type: cannot read the analysed DEM (%s)", exc)
    return None
