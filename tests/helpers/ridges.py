"""Ridge sets of pruned Divide Trees, to compare two engines' trees exactly."""
from __future__ import annotations


def ridge_set(tree) -> set[tuple[int, int, int]]:
    """Ridges as (lower peak cell, higher peak cell, saddle cell): the pruned tree itself."""
    pc = (tree.peaks["row"] * 10**9 + tree.peaks["col"]).to_numpy()
    sc = (tree.saddles["row"] * 10**9 + tree.saddles["col"]).to_numpy()
    e = tree.edges
    return {(int(min(pc[a], pc[b])), int(max(pc[a], pc[b])), int(sc[s]))
            for a, b, s in zip(e["peak_a"], e["peak_b"], e["saddle"])}


def orometry_ridges(o) -> set[tuple[int, int, int]]:
    c = o.peak_cell
    return {(int(min(c[a], c[b])), int(max(c[a], c[b])), int(s)) for a, b, s in zip(o.ridge_a, o.ridge_b,
                                                                                    o.ridge_saddle_cell)}
