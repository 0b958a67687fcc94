"""``--generator``, ``--param``, ``--exemplar`` and ``--list-generators`` (render, synthesize)."""
from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

from orokit.io.hashing import sha256_file

__all__ = ["generator_options", "check_generator_inputs", "render_generator", "file_inputs", "EXTRA_TAGS"]

#: raster attrs written as COG tags besides those :func:`write_cog` always writes
EXTRA_TAGS = ("generator_paper", "tree_sha256", "tree_file_sha256", "exemplar_sha256", "coarse_sha256",
              "generators_sha256", "map_sha256", "cell_counts", "derived", "n_tree_peaks")


def _list_generators(ctx: click.Context, param: click.Parameter, value: bool) -> None:
    if not value or ctx.resilient_parsing:
        return
    from orokit.generators import describe_generators

    click.echo(describe_generators())
    ctx.exit(0)


def generator_options(f: Callable[..., Any]) -> Callable[..., Any]:
    """Add the generator options to a command (values: generator, params, exemplar)."""
    from orokit.generators import GENERATORS

    f = click.option("--list-generators", is_flag=True, expose_value=False, is_eager=True,
                     callback=_list_generators, help="List the generators, their inputs and defaults, and exit.")(f)
    f = click.option("--exemplar", default=None,
                     help="Real DEM a generator learns from, a file or a manifest dataset name (generators whose "
                          "inputs include 'exemplar').")(f)
    f = click.option("--param", "params", multiple=True, metavar="K=V",
                     help="Generator parameter (repeatable), e.g. --param hurst=0.8; see --list-generators.")(f)
    f = click.option("--generator", type=click.Choice(sorted(GENERATORS)), default="argudo", show_default=True,
                     help="Terrain generator (one per paper).")(f)
    return f


def exemplar_dem(exemplar: str):
    """The exemplar DEM (a file, else a manifest dataset) and the sha256 of its file."""
    from orokit.errors import DataError, InputError
    from orokit.io.dem import read_dem

    if Path(exemplar).is_file():
        return read_dem(str(exemplar)), sha256_file(Path(exemplar))
    from orokit.data import dataset_path, open_dataset_dem

    try:
        return open_dataset_dem(exemplar), sha256_file(dataset_path(exemplar))
    except (DataError, KeyError):
        raise InputError(f"exemplar {exemplar!r} is neither a DEM file nor a dataset of the manifest; "
                         "pass an existing DEM to --exemplar") from None


def check_generator_inputs(generator: str, params: tuple[str, ...], exemplar: str | None) -> Any:
    """Parsed parameters; errors for bad parameters or a missing/unneeded exemplar."""
    from orokit.generators import get_generator

    spec = get_generator(generator)
    parsed = spec.params(list(params))
    if exemplar is not None:
        if "exemplar" not in spec.inputs:
            raise click.UsageError(f"--generator {generator} takes no --exemplar")
    return parsed


def file_inputs(params: Any) -> tuple[dict[str, Any], dict[str, str]]:
    """Read the file-valued parameters of a backend (fields with ``metadata={"file": kind}``).

    ``dem``: a DEM file or manifest dataset (:func:`exemplar_dem`); ``table``: a CSV file
    (pandas); ``vector``: a vector map (:func:`orokit.io.vector_map_io.read_vector_map`). Returns the data by parameter name and their
    sha256 (``<name>_sha256``) for the raster tags.
    """
    import dataclasses

    from orokit.errors import InputError

    data: dict[str, Any] = {}
    hashes: dict[str, str] = {}
    for f in dataclasses.fields(params):
        kind = f.metadata.get("file") if f.metadata else None
        value = getattr(params, f.name)
        if not kind or not value:
            continue
        if kind == "dem":
            try:
                data[f.name], hashes[f"{f.name}_sha256"] = exemplar_dem(str(value))
            except InputError:
                raise InputError(f"--param {f.name}={value}: neither a DEM file nor a dataset of the manifest; "
                                 "pass an existing DEM") from None
        elif kind == "vector":
            from orokit.io.vector_map_io import read_vector_map

            data[f.name] = read_vector_map(str(value))
            hashes[f"{f.name}_sha256"] = sha256_file(Path(str(value)))
        else:
            import pandas as pd

            path = Path(str(value))
            if not path.is_file():
                raise InputError(f"--param {f.name}={value}: no such file; pass an existing CSV file")
            try:
                data[f.name] = pd.read_csv(path)
            except (ValueError, OSError) as exc:
                raise InputError(f"--param {f.name}={value}: not a readable CSV file ({exc})") from None
            hashes[f"{f.name}_sha256"] = sha256_file(path)
    return data, hashes


def render_generator(tree, *, generator: str, params: Any, cell_size_m: float, extent, seed: int | None,
                     tree_path: Path | None = None, exemplar: str | None = None):
    """Render with a registered generator; records the input files' hashes in the attrs."""
    from orokit.generators import render_terrain

    ex = ex_sha = None
    if exemplar is not None:
        ex, ex_sha = exemplar_dem(exemplar)
    inputs, hashes = file_inputs(params)
    dem = render_terrain(tree, generator=generator, params=params, cell_size_m=cell_size_m, extent=extent,
                         seed=seed, exemplar=ex, inputs=inputs)
    dem.attrs.update(hashes)
    if tree_path is not None and Path(tree_path).is_file():
        dem.attrs["tree_file_sha256"] = sha256_file(Path(tree_path))
    if ex_sha is not None:
        dem.attrs["exemplar_sha256"] = ex_sha
    return dem
