"""Calibration and open-set page of the classification report: ``calibration.md`` with its figures.

Files (``<R>`` the radius tag, e.g. ``10km``)::

    calibration.md                     the numbers in words and tables
    figures/reliability_<R>.png        reliability diagrams, disks and terrain answers, before / after
    figures/open_set_<R>.png           leave-one-region-out: how often a region the model never saw is 'unknown'
    tables/open_set_<R>.csv            the same per left-out region
"""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from orokit._typing import PathLike
from orokit.reports.classification import _km, _save, _write_text, to_markdown

if TYPE_CHECKING:  # pragma: no cover
    from orokit.classify.train import Evaluation, OpenSetEvaluation


def calibration_files(radius_m: float, outdir: PathLike, *, open_set: bool) -> list[Path]:
    """Files :func:`write_calibration_page` writes."""
    out = Path(outdir)
    tag = f"{float(radius_m) / 1000:g}km"
    files = [out / "calibration.md", out / "figures" / f"reliability_{tag}.png"]
    if open_set:
        files += [out / "figures" / f"open_set_{tag}.png", out / "tables" / f"open_set_{tag}.csv"]
    return files


def plot_reliability(axes: Any, check: dict[str, Any]) -> None:
    """Two panels (disks, terrain answers): share right against mean top probability per bin,
    raw and calibrated, with the number of answers per bin as bars."""
    for ax, level, title in zip(axes, ("disks", "terrain"), ("held-out disks", "terrain answers (held-out strips)")):
        d = check[level]
        ax.plot([0, 1], [0, 1], color="0.6", lw=0.8, ls="--")
        for key, color, name in (("raw", "tab:red", "forest"), ("calibrated", "tab:blue", "calibrated")):
            rel = d[f"reliability_{key}"]
            m = rel["n"] > 0
            sc = d[key]
            ax.plot(rel["confidence"][m], rel["accuracy"][m], "o-", color=color, ms=3,
                    label=f"{name}: ECE {sc['ece']:.3f}, Brier {sc['brier']:.3f}, log-loss {sc['log_loss']:.3f}")
        ax2 = ax.twinx()
        rel = d["reliability_calibrated"]
        ax2.bar(0.5 * (rel["lo"] + rel["hi"]), rel["n"], width=0.09, color="tab:blue", alpha=0.15)
        ax2.set_yticks([])
        ax.set_xlim(0, 1)
        ax.set_ylim(0, 1)
        ax.set_xlabel("top probability (bin mean)", fontsize=8)
        ax.set_ylabel("share right", fontsize=8)
        ax.set_title(f"{title}: {d['raw']['n']}", fontsize=8)
        ax.legend(fontsize=6, loc="upper left")
        ax.tick_params(labelsize=7)


def plot_open_set(ax: Any, rows: list[dict[str, Any]]) -> None:
    """Per left-out region: share of its disks answered unknown against the known regions' held-out disks."""
    names = [r["region"] for r in rows]
    x = np.arange(len(rows))
    ax.bar(x - 0.2, [100 * r["unknown_disks"] for r in rows], 0.4, color="tab:orange",
           label="left-out region's disks answered unknown")
    ax.bar(x + 0.2, [100 * r["known_unknown_disks"] for r in rows], 0.4, color="tab:blue",
           label="known regions' held-out disks answered unknown")
    for xi, r in zip(x, rows):
        ax.text(xi - 0.2, 100 * r["unknown_disks"] + 1, f"→{r['answered_as']}", rotation=90, fontsize=6,
                ha="center", va="bottom")
    ax.set_xticks(x)
    ax.set_xticklabels(names, rotation=45, ha="right", fontsize=7)
    ax.set_ylabel("%", fontsize=8)
    ax.set_ylim(0, 115)
    ax.legend(fontsize=7, loc="upper right")
    ax.tick_params(labelsize=7)


def _scores_table(check: dict[str, Any]) -> pd.DataFrame:
    rows = []
    for level, name in (("disks", "held-out disks"), ("terrain", "terrain answers")):
        for key in ("raw", "calibrated"):
            s = check[level][key]
            rows.append({"answers": name, "probabilities": "forest" if key == "raw" else "calibrated",
                         "n": s["n"], "accuracy %": 100 * s["accuracy"], "log-loss": s["log_loss"],
                         "Brier": s["brier"], "ECE": s["ece"]})
    return pd.DataFrame(rows).set_index("answers")


def write_calibration_page(spatial: Evaluation, open_set: OpenSetEvaluation | None, outdir: PathLike, *,
                           radius_m: float, command: str = "") -> Path:
    """Write ``calibration.md`` and its figures for the spatial evaluation ``spatial`` (and the
    leave-one-region-out test ``open_set``, if given) into ``outdir``."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    out = Path(outdir)
    tag = f"{float(radius_m) / 1000:g}km"
    cal = spatial.calibration()
    check = spatial.calibration_check()
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2))
    plot_reliability(axes, check)
    fig.suptitle(f"Reliability on the spatial hold-out, R = {_km(radius_m)} (each region calibrated on the others)",
                 fontsize=9)
    _save(fig, out / "figures" / f"reliability_{tag}.png")
    plt.close(fig)
    d, t = check["disks"], check["terrain"]
    lines = [f"# Calibrated probabilities and the 'unknown' answer (R = {_km(radius_m)})", "",
             f"{command}" if command else "", "",
             "A forest's class probabilities are vote shares, not calibrated probabilities. orokit rescales them "
             "by temperature, `softmax(log(p) / T)` with the disks' probabilities floored at 0.001, with `T` "
             "fitted by minimising the log-loss of the **spatial hold-out's** predictions (disks more than "
             f"{spatial.params.get('buffer_m', 2 * radius_m) / 1000:g} km from every training disk, "
             f"{len(spatial.accuracies)} runs). One `T` for every class: it never changes the best class of a "
             "disk, nor of a terrain. The terrain posterior (the disks' summed log-probabilities, which count "
             "overlapping disks as independent evidence) gets its own temperature, fitted on the held-out "
             "strips' terrain answers.", "",
             f"The model's calibration (fitted on all {len(spatial.heldout_true)} held-out disks): disk "
             f"temperature **{cal.temperature:.3f}** ({'sharpens' if cal.temperature < 1 else 'flattens'} the "
             f"forest's probabilities), terrain temperature **{cal.terrain_temperature:.2f}**; 'unknown' thresholds "
             f"keeping {100 * cal.keep:.0f} % of the right held-out answers: a disk below **{cal.disk_threshold:.3f}**"
             f", a terrain (mean calibrated probability of its best region over its disks) below "
             f"**{cal.terrain_threshold:.3f}**.", "",
             "## Before and after, measured on ground the calibration did not see", "",
             "Each region's held-out disks are calibrated with temperatures and thresholds fitted on the "
             "*other* regions' held-out disks, so no score below was fitted on the answers it scores. "
             "ECE: expected calibration error of the top class (10 bins); Brier: summed squared error over the "
             "classes; log-loss of the true class.", "",
             to_markdown(_scores_table(check), floatfmt=".3f"), "",
             f"'unknown' on this known ground: {100 * d['unknown_right']:.1f} % of the right disk answers and "
             f"{100 * d['unknown_wrong']:.1f} % of the wrong ones; {100 * t['unknown_right']:.1f} % of the right "
             f"terrain answers and {100 * t['unknown_wrong']:.1f} % of the wrong ones.", "",
             f"![reliability](figures/reliability_{tag}.png)", ""]
    if open_set is not None and open_set.rows:
        sm = open_set.summary()
        p = open_set.params
        tab = pd.DataFrame([{
            "left-out region": r["region"], "runs": r["runs"], "disks": r["disks"],
            "its disks unknown %": 100 * r["unknown_disks"], "its terrain unknown %": 100 * r["unknown_terrain"],
            "else answered as": f"{r['answered_as']} ({100 * r['answered_as_share']:.0f} %)",
            "known disks unknown %": 100 * r["known_unknown_disks"],
            "known strips unknown %": 100 * r["known_unknown_terrain"], "AUROC": f"{r['auroc']:.2f}"}
            for r in open_set.rows]).set_index("left-out region")
        _write_text(out / "tables" / f"open_set_{tag}.csv", tab.to_csv(float_format="%.3f"))
        fig, ax = plt.subplots(figsize=(9, 4.2))
        plot_open_set(ax, open_set.rows)
        ax.set_title(f"One region left out of training, R = {_km(radius_m)}: mean {100 * sm['unknown_disks']:.0f} % "
                     f"of its disks unknown vs {100 * sm['known_unknown_disks']:.0f} % of the known regions' "
                     f"held-out disks (AUROC {sm['auroc']:.2f})", fontsize=8)
        _save(fig, out / "figures" / f"open_set_{tag}.png")
        plt.close(fig)
        lines += ["## Regions the model never saw (leave one region out)", "",
                  f"For each region, {p['runs']} runs: a model is trained on the spatial hold-out split of the "
                  f"*other* regions (training disks > {p['buffer_m'] / 1000:g} km from their held-out strips), "
                  "calibrated on their held-out disks exactly as a model is (same temperatures, thresholds keeping "
                  f"{100 * p['keep']:.0f} % of right answers), and then asked about every disk of the left-out "
                  "region. The left-out region's terrain answer takes all its disks together (one per run). The "
                  "known regions' rates use, for each known region, a calibration fitted without it. AUROC: how "
                  "well the calibrated top probability tells the known regions' held-out disks from the left-out "
                  "region's (1 = perfectly, 0.5 = chance). Nothing is tuned on the left-out region.", "",
                  f"Mean over the {len(open_set.rows)} left-out regions: **{100 * sm['unknown_disks']:.1f} %** of "
                  f"their disks and **{100 * sm['unknown_terrain']:.1f} %** of their terrain answers are 'unknown', "
                  f"against **{100 * sm['known_unknown_disks']:.1f} %** of the known regions' held-out disks and "
                  f"**{100 * sm['known_unknown_terrain']:.1f} %** of their held-out strips; AUROC "
                  f"**{sm['auroc']:.2f}**.", "",
                  to_markdown(tab, floatfmt=".1f"), "",
                  f"![open set](figures/open_set_{tag}.png)", ""]
    path = out / "calibration.md"
    _write_text(path, "\n".join(lines).replace("\n\n\n", "\n\n") + "\n")
    return path
