"""``orokit data list | fetch [NAMES] | verify [NAMES] | path NAME``."""
from __future__ import annotations

import json

import click

from orokit.cli.options import progress_option


@click.group("data")
def data() -> None:
    """Real datasets of the manifest: list, fetch (cache or OROKIT_DATA_MIRROR), verify sha256."""


@data.command("list")
@click.option("--json", "as_json", is_flag=True, help="Print the datasets as JSON.")
def list_cmd(as_json: bool) -> None:
    """List the datasets of the manifest and whether they are cached."""
    from orokit.data import data_dir, load_manifest

    man = load_manifest()
    root = data_dir()
    rows = []
    for ds in man:
        cached = sum((root / f.path).is_file() for f in ds.files)
        rows.append(
            {
                "name": ds.name, "kind": ds.kind, "region": ds.region or "", "format": ds.format,
                "z_units": ds.z_units or "", "cell_size_m": ds.cell_size_m, "crs": ds.crs or "",
                "files": len(ds.files), "cached": cached, "title": ds.title,
            }
        )
    if as_json:
        click.echo(json.dumps(rows, indent=2))
        return
    click.echo(f"manifest: {man.path}\ncache:    {root}")
    header = f"{'name':<20} {'kind':<8} {'region':<16} {'format':<14} {'units':<6} {'cell (m)':>9} {'crs':<11} files"
    click.echo(header)
    for r in rows:
        cell = "" if r["cell_size_m"] is None else f"{r['cell_size_m']:.2f}"
        click.echo(
            f"{r['name']:<20} {r['kind']:<8} {r['region']:<16} {r['format']:<14} {r['z_units']:<6} "
            f"{cell:>9} {r['crs']:<11} {r['cached']}/{r['files']}"
        )


@data.command("fetch")
@click.argument("names", nargs=-1)
@click.option("--force", is_flag=True, help="Fetch again even when the cached copy is good.")
@progress_option()
@click.pass_context
def fetch_cmd(ctx: click.Context, names: tuple[str, ...], force: bool, progress: bool) -> None:
    """Fetch NAMES (default: all datasets) into the cache, checking sha256.

    Copies from $OROKIT_DATA_MIRROR when it is set, else downloads the URLs.
    """
    from orokit.data import data_dir, fetch

    quiet = bool(ctx.find_root().obj and ctx.find_root().obj.get("quiet"))
    out = fetch(list(names), force=force, progress=progress and not quiet)
    n = len({str(p) for paths in out.values() for p in paths})  # a file shared by datasets counts once, as in verify
    if not quiet:
        click.echo(f"{len(out)} dataset(s), {n} file(s) ready in {data_dir()}")


@data.command("verify")
@click.argument("names", nargs=-1)
@click.option(
    "--root", type=click.Path(file_okay=False, exists=True), default=None,
    help="Directory to check instead of the cache (e.g. a mirror).",
)
@click.pass_context
def verify_cmd(ctx: click.Context, names: tuple[str, ...], root: str | None) -> None:
    """Check the sha256 of every file of NAMES (default: all) in the cache; exit 1 on any problem."""
    from orokit.data import verify
    from orokit.errors import DataError

    results = verify(list(names), root=root)
    bad = [r for r in results if r.status != "ok"]
    quiet = bool(ctx.find_root().obj and ctx.find_root().obj.get("quiet"))
    for r in bad:
        detail = "missing (run: orokit data fetch)" if r.status == "missing" else f"expected {r.expected}, got {r.actual}"
        click.echo(f"{r.status.upper()} {r.path}: {detail}", err=True)
    if bad:
        raise DataError(f"{len(bad)} of {len(results)} file(s) failed verification (listed above).")
    if not quiet:
        click.echo(f"all {len(results)} file(s) verified")


@data.command("path")
@click.argument("name")
@click.option("--role", default=None, help="File role within the dataset (dem, divide_tree, licence...).")
def path_cmd(name: str, role: str | None) -> None:
    """Print the local path of NAME (a dataset or a manifest file), fetching it if needed."""
    from orokit.data import dataset_path

    click.echo(str(dataset_path(name, role=role)))
