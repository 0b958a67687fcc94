"""``orokit synthesis-report``: fidelity table of synthesized Divide Trees (markdown)."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import click

from orokit.cli.options import overwrite_option, refuse_existing

#: the paper's reported maximum histogram errors (Argudo et al. 2019, section 7.1)
PAPER_MAX_ERROR = {"prominence": 0.03, "dominance": 0.03, "isolation_distance": 0.08}


@click.command(name="synthesis-report")
@click.argument("trees", nargs=-1, required=True, type=click.Path(exists=True, file_okay=False, path_type=Path))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="Markdown file to write.")
@overwrite_option("an existing OUTPUT")
def synthesis_report(trees: tuple[Path, ...], output: Path, overwrite: bool) -> None:
    """Tabulate per-feature fidelity of `orokit synthesize-tree` output folders TREES."""
    import pandas as pd

    from orokit.io.atomic import write_text_atomic

    from orokit.cli.outputs import claim_outputs

    claim_outputs(output)  # locked for the whole run
    refuse_existing(output, overwrite=overwrite)
    rows: list[dict[str, Any]] = []
    runs: list[Any] = []
    times: list[Any] = []
    for d in trees:
        meta_path = d / "synthesis.json"
        if not meta_path.is_file():
            raise click.BadParameter(f"{d} has no synthesis.json; run `orokit synthesize-tree -o {d}` first",
                                     param_hint="TREES")
        meta = json.loads(meta_path.read_text(encoding="utf-8"))
        if "fidelity" not in meta:
            raise click.BadParameter(f"{meta_path} has no fidelity table (several types?)", param_hint="TREES")
        name = d.name if d.name not in {r["type"] for r in runs} else str(d)  # rows keyed by folder
        t = meta.get("timings_s", {})
        runs.append({"type": name, "peaks": meta.get("n_peaks"), "OT rounds": meta.get("ot_iterations"),
                     "peaks < eps": meta.get("peaks_below_eps")})
        times.append({"type": name, "peaks": meta.get("n_peaks"), "seconds": t.get("total"),
                      "dart_throwing_s": t.get("dart_throwing"), "saddle_ot_s": t.get("saddle_elevations")})
        for f in meta["fidelity"]:
            rows.append({"type": name, **f})
    fid = pd.DataFrame(rows)
    err = fid.pivot(index="type", columns="feature", values="max_bin_error")
    emd = fid.pivot(index="type", columns="feature", values="emd")
    lines = [
        "# Divide Tree synthesis: fidelity per terrain type",
        "",
        "Each type comes from `orokit type` on the region's analysis (eps = 30 m); each tree is a",
        "90 x 90 km `orokit synthesize-tree --seed 0`. Errors are maximum absolute differences between",
        "normalised histograms of the synthesized tree and of the type, on the type's bins (40 for",
        "magnitudes, 24 for directions). Isolation is to the nearest higher peak on both sides.",
        "Timings of the last run are in `timings.csv` beside this page (not committed: they change with",
        "the machine's load).",
        "",
        "## Runs",
        "",
        _markdown(pd.DataFrame(runs).set_index("type"), "{:.3f}"),
        "",
        "## Maximum histogram-bin error",
        "",
        _markdown(err, "{:.4f}"),
        "",
        "## Earth mover's distance (feature units: m, 1, degrees)",
        "",
        _markdown(emd, "{:.4g}"),
        "",
        "## Against the paper (worst type)",
        "",
    ]
    for feat, bound in PAPER_MAX_ERROR.items():
        worst = float(err[feat].max())
        lines.append(f"- {feat}: worst {worst:.4f} (paper: up to {bound:.2f})")
    worst_sd = float(err["saddle_distance"].max())
    lines.append(f"- saddle_distance: worst {worst_sd:.4f} (not a target of the paper's algorithm)")
    import os

    timings = pd.DataFrame(times).assign(load_average_1min=os.getloadavg()[0])
    write_text_atomic(output.parent / "timings.csv", timings.to_csv(index=False, float_format="%.3f"))
    write_text_atomic(output, "\n".join(lines) + "\n")
    click.echo(f"fidelity of {len(runs)} trees -> {output}")


def _markdown(frame, fmt: str) -> str:
    """A DataFrame as a markdown table (index first)."""
    def cell(v) -> str:
        return fmt.format(v) if isinstance(v, float) else str(v)

    head = [str(frame.index.name or ""), *map(str, frame.columns)]
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for idx, row in frame.astype(object).iterrows():
        out.append("| " + " | ".join([str(idx), *(cell(v) for v in row.tolist())]) + " |")
    return "\n".join(out)
