"""``orokit compare``: match two peak lists (orokit, Kirmse, reference trees) and report agreement."""
from __future__ import annotations

from pathlib import Path

import click

from orokit.cli.options import LENGTH, Length, cell_size_option, overwrite_option, progress_option, refuse_existing


@click.command()
@click.argument("a", type=click.Path(exists=True, path_type=Path))
@click.argument("b", type=click.Path(exists=True, path_type=Path))
@click.option("--cells", "max_cells", type=click.FloatRange(min=0), default=1.0, show_default=True,
              help="Match peaks within this many cells when both lists are on one raster grid (row/col).")
@click.option("--distance", "max_distance_m", type=LENGTH, default="100m", show_default=True,
              help="Match peaks within this distance otherwise (lat/lon or x/y; a length: 100m, 300ft).")
@click.option("--z-tolerance", "z_tolerance_m", type=Length(allow_zero=True), default="0.01m", show_default=True,
              help="Elevations and prominences agree within this (a length).")
@cell_size_option(help="Cell size of reference .txt Divide Trees")
@click.option("--tree-z-units", type=click.Choice(["m", "ft"]), default="ft", show_default=True,
              help="Elevation units of reference .txt Divide Trees.")
@click.option("--tree-rows", type=click.IntRange(min=1), default=None,
              help="Rows of the DEM a reference .txt Divide Tree belongs to (gives its peaks' raster rows).")
@click.option("--csv", "csv_path", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Also write every matched, missing (in B only) and extra (in A only) peak to this CSV.")
@overwrite_option("an existing --csv file")
@progress_option()
def compare(a: Path, b: Path, max_cells: float, max_distance_m: float, z_tolerance_m: float,
            cell_size_m: float | None, tree_z_units: str, tree_rows: int | None, csv_path: Path | None, overwrite: bool,
            progress: bool) -> None:
    """Compare peak list A (under test) with B (reference).

    A and B are analysis folders or peaks tables (orokit), Divide Trees (.gpkg,
    reference .txt, Kirmse .dvt: prominences and parents from the tree) or Kirmse
    peak lists (results.txt, compute_parents output). Prints the location precision
    and recall, the agreement of elevation and prominence, the (elevation,
    prominence) precision and recall regardless of location, and the line and
    prominence parent agreement of matched peaks.
    """
    from orokit.cli.progress import StageProgress
    from orokit.io.peak_lists import read_peak_list
    from orokit.metrics.peak_match import compare_peak_lists

    if csv_path is not None:
        from orokit.cli.outputs import claim_outputs

        claim_outputs(csv_path)
        refuse_existing(csv_path, overwrite=overwrite)
    with StageProgress("compare", [f"read {a.name}", f"read {b.name}", "match"], enabled=progress) as bar:
        ta = read_peak_list(a, cell_size_m=cell_size_m, z_units=tree_z_units, height=tree_rows)
        bar.advance()
        tb = read_peak_list(b, cell_size_m=cell_size_m, z_units=tree_z_units, height=tree_rows)
        bar.advance()
        summary, pairs = compare_peak_lists(ta, tb, max_cells=max_cells, max_distance_m=max_distance_m,
                                            z_tolerance_m=z_tolerance_m)
        bar.advance()
    unit = "cells" if summary["match_unit"] == "cells" else "m"

    def pct(v: float) -> str:
        return "n/a" if v != v else f"{100 * v:.1f} %"

    rows = [
        ("peaks in A / B", f"{summary['peaks_a']} / {summary['peaks_b']}"),
        (f"matched within {summary['match_radius']:g} {unit}", str(summary["matched"])),
        ("location precision / recall", f"{pct(summary['location_precision'])} / {pct(summary['location_recall'])}"),
        (f"matched: elevation and prominence within {z_tolerance_m:g} m", pct(summary["matched_values_agree"])),
        ("(elevation, prominence) precision / recall",
         f"{pct(summary['value_precision'])} / {pct(summary['value_recall'])}"),
        ("matched: median / max |prominence difference|",
         f"{summary['median_abs_prominence_diff']:.2f} / {summary['max_abs_prominence_diff']:.2f} m"),
        (f"line parent agrees ({summary['line_parent_compared']} compared)", pct(summary["line_parent_agree"])),
        (f"prominence parent agrees ({summary['prominence_parent_compared']} compared)",
         pct(summary["prominence_parent_agree"])),
    ]
    width = max(len(r[0]) for r in rows)
    for k, v in rows:
        click.echo(f"{k:<{width}}  {v}")
    if csv_path is not None:
        from orokit.io.atomic import write_text_atomic

        write_text_atomic(csv_path, pairs.to_csv(index=False))
