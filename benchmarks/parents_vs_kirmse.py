"""Line and prominence parents: orokit against Kirmse's ``compute_parents`` (issue 16).

For each DEM (manifest dataset names or raster paths; default: every shared DEM):

1. integer feet of the DEM are written for both programs as in ``vs_kirmse.py`` (Kirmse:
   one CUSTOM FLT tile of z / 32, turned by 180 degrees so both break ties alike; orokit:
   a float32 GeoTIFF in metres);
2. Kirmse: ``prominence -t 1``, ``merge_divide_trees -f`` (the finalized tree, no runoffs)
   and ``compute_parents -m EPS`` on it; orokit: ``orokit analyze --min-prominence EPS``;
3. orokit's parents (tree pruned at EPS) are also checked against the walk on its
   *unpruned* tree (:func:`unpruned_walk_check`), which pruning must not change;
4. peaks are matched by cell (a Kirmse peak on a flat summit moved to the summit's first
   cell, orokit's convention), and so are both parents of every matched peak.

A prominence parent disagreement is also a *tie* when orokit's parent has P's prominence
(in feet): orokit counts the higher of two equally prominent peaks as more prominent, Kirmse's
``compute_parents`` needs a strictly larger prominence. A disagreement is a *tie* when two of the peaks on either program's walk from the peak to the
farther of the two parents (the chain of its line parents) have the same elevation (Kirmse
takes the first peak at least as high, orokit the first strictly higher one in its
raster-order tie rule, and Kirmse's line tree and island tree may order equal peaks
differently), or when either parent is on a flat summit. It is an *edge* case when
either walk, or P's key saddle, touches the raster's border (Kirmse's finalized tree
drops the runoffs there; orokit keeps the border as unknown ground). It is a *key_saddle_tie*
when the lowest saddles on the walks to the two parents (orokit's unpruned tree) are different cells
of the same elevation, or when Kirmse's key saddle of P and orokit's are different cells of the same
elevation: P's key saddle is a tie between two saddles. It is a *kirmse_walk*
case when, at P's key saddle or at a saddle of orokit's unpruned tree where the walks to the
two parents have not parted yet, Kirmse's uphill walk from the saddle (``TreeBuilder::walkUpToPeak``,
simulated by :func:`kirmse_walk_up`) reaches another peak than orokit's steepest ascent
(:func:`orokit_walk_up`): his walk leaves a saddle cell it steps on by that saddle's first rise
(the highest cell of a group of higher neighbours that is not the highest group), and takes the
last of equal highest neighbours in our raster order where orokit takes the first, so his divide
tree ties the saddle to a peak on another branch (both trees keep every prominence; the walks
differ). ``tests/benchmarks/test_vs_kirmse.py`` reproduces one on an 11 x 11 grid with Kirmse's
own programs. It is *kirmse_line_tree* (checked right after the ties) when the walk on
*Kirmse's own* divide tree (:func:`kirmse_tree_walk`: orokit's ``DivideTree.parents`` on his ``.dvt``)
gives orokit's parent: his ``compute_parents`` disagrees with his own tree because his ``LineTree``
walks towards the root stored in the file, which ``merge_divide_trees -f`` leaves at a peak that
is not the highest (:func:`reroot_kirmse_tree` roots the same tree at its highest peak, and his
``compute_parents`` on it is run and compared too: ``kirmse_rerooted_agree``). It is a *saddle_fork*
when a saddle of the walks (as for *kirmse_walk*) has higher neighbours climbing to three or more
peaks (:func:`saddle_fork`): the ridge beyond it forks at the saddle cell, both trees are maximum
spanning trees, and the programs take different branches. Every other disagreement is counted as
unexplained and printed with the walk on Kirmse's tree.

Run:  .venv/bin/python benchmarks/parents_vs_kirmse.py --kirmse-bin DIR [--dems gobi alaska my.tif]
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).parent))
from vs_kirmse import (  # noqa: E402
    EPS_FT, FT, SCALE, _plateau_first_cell, build_kirmse, kirmse_commands, orokit_command, timed,
    write_geotiff_m, write_kirmse_tile,
)

DATASETS = ["alaska", "andes-aconcagua", "andes-chile", "appalachians", "gobi", "highlands", "himalaya-annapurna",
            "himalaya-everest", "karakoram", "norway", "pyrenees", "rockies", "sahara"]


def dem_feet(name: str) -> np.ndarray:
    """Integer feet of a manifest dataset or a raster file (NaN = nodata)."""
    if Path(name).exists():
        from orokit.io.dem import read_dem

        z = np.asarray(read_dem(name).values, np.float64)
    else:
        from orokit.data import open_dataset_dem

        z = np.asarray(open_dataset_dem(name).values, np.float64)
    return np.rint(z / FT)


def kirmse_parents(path: Path, s: int, shape: tuple[int, int]) -> pd.DataFrame:
    """``compute_parents`` output as cells: row, col, elevation (ft), prominence (ft) and both
    parents' cells (-1 for none), turned back by 180 degrees."""
    from orokit.io.kirmse_io import read_kirmse_peaks

    k = read_kirmse_peaks(path)
    h, w = shape

    def cells(lat: pd.Series, lon: pd.Series) -> tuple[np.ndarray, np.ndarray]:
        lat_a, lon_a = lat.to_numpy(float), lon.to_numpy(float)
        none = ~np.isfinite(lat_a) | ((lat_a == 0) & (lon_a == 0))
        r = h - 1 - np.rint((1.0 - np.nan_to_num(lat_a)) * s).astype(np.int64)
        c = w - 1 - np.rint(np.nan_to_num(lon_a) * s).astype(np.int64)
        r[none], c[none] = -1, -1
        return r, c

    row, col = cells(k["lat"], k["lon"])
    sr, sc = cells(k["saddle_lat"], k["saddle_lon"])
    lr, lc = cells(k["line_parent_lat"], k["line_parent_lon"])
    pr, pc = cells(k["prominence_parent_lat"], k["prominence_parent_lon"])
    return pd.DataFrame({"row": row, "col": col, "elevation": np.rint(k["elevation"].to_numpy() * SCALE),
                         "prominence": np.rint(k["prominence"].to_numpy() * SCALE),
                         "saddle_row": sr, "saddle_col": sc, "line_parent_row": lr, "line_parent_col": lc,
                         "prominence_parent_row": pr, "prominence_parent_col": pc})


def kirmse_tree_walk(dvt: Path, shape: tuple[int, int]) -> pd.DataFrame:
    """The walk of :meth:`orokit.topology.divide_tree.DivideTree.parents` on *Kirmse's own* divide
    tree (the ``.dvt`` that ``compute_parents`` reads): row, col and both parents' cells of every
    peak of it (-1 for none), turned back by 180 degrees like :func:`kirmse_parents`."""
    from orokit.io.kirmse_io import read_kirmse_tree

    t = read_kirmse_tree(dvt)
    h, w = shape
    row = h - 1 - t.peaks["y"].to_numpy(np.int64)
    col = w - 1 - t.peaks["x"].to_numpy(np.int64)
    par = t.parents()
    out = {"row": row, "col": col}
    for kind in ("line_parent", "prominence_parent"):
        i = par[kind].to_numpy(np.int64)
        out[f"{kind}_row"] = np.where(i >= 0, row[i], -1)
        out[f"{kind}_col"] = np.where(i >= 0, col[i], -1)
    return pd.DataFrame(out)


def reroot_kirmse_tree(src: Path, dst: Path) -> None:
    """Write Kirmse's divide tree ``src`` to ``dst`` rooted at its highest peak (same peaks, saddles
    and edges; only the direction of the ``N`` parent records changes). ``merge_divide_trees -f``
    stores trees rooted at other peaks; his ``LineTree`` (what ``compute_parents`` walks) assumes
    the root is the highest peak, so running ``compute_parents`` on both files shows which of his
    parents come from the stored root (class ``kirmse_line_tree``)."""
    lines = src.read_text().splitlines()
    elev, adj = {}, {}
    for ln in lines:
        f = ln.split(",")
        if f[0] == "P":
            elev[int(f[1])] = float(f[4])
        elif f[0] == "N" and int(f[1]) > 0 and int(f[2]) > 0:
            adj.setdefault(int(f[1]), []).append((int(f[2]), int(f[3])))
            adj.setdefault(int(f[2]), []).append((int(f[1]), int(f[3])))
    parent: dict[int, tuple[int, int]] = {}
    for top in sorted(elev, key=lambda i: (-elev[i], i)):  # every connected part from its highest peak
        if top in parent:
            continue
        parent[top] = (-1, -1)
        stack = [top]
        while stack:
            u = stack.pop()
            for v, sid in adj.get(u, []):
                if v not in parent:
                    parent[v] = (u, sid)
                    stack.append(v)
    out = [ln for ln in lines if not ln.startswith("N,")] + ["N,0,-1,-1"]
    out += [f"N,{i},{parent[i][0]},{parent[i][1]}" for i in sorted(elev)]
    dst.write_text("\n".join(out) + "\n")


def compare(kirmse: pd.DataFrame, ours: pd.DataFrame, z_ft: np.ndarray, tree=None,
            kirmse_walk_table: pd.DataFrame | None = None) -> dict:
    """Parent agreement of the peaks both programs find (see the module docstring); ``tree`` is
    orokit's unpruned Divide Tree, needed for the ``kirmse_walk`` class; ``kirmse_walk_table``
    (:func:`kirmse_tree_walk`) the walk on Kirmse's own tree, needed for ``kirmse_line_tree``."""
    def first(r: int, c: int) -> tuple[int, int]:
        return (r, c) if r < 0 else _plateau_first_cell(z_ft, r, c)

    o = ours.set_index(["row", "col"])
    kk = kirmse.set_index(["row", "col"])
    kk = kk[~kk.index.duplicated()]
    kw = None
    if kirmse_walk_table is not None:
        kw = {first(r, c): tuple(first(int(getattr(rec, f"{k}_row")), int(getattr(rec, f"{k}_col")))
                                  for k in ("line_parent", "prominence_parent"))
              for rec in kirmse_walk_table.itertuples(index=False) for r, c in [(int(rec.row), int(rec.col))]}
    out = {"kirmse_peaks": len(kirmse), "orokit_peaks": len(ours), "matched": 0}
    for kind in ("line_parent", "prominence_parent"):
        out[kind] = {"agree": 0, "tie": 0, "kirmse_line_tree": 0, "edge": 0, "key_saddle_tie": 0, "kirmse_walk": 0,
                     "saddle_fork": 0, "unexplained": 0, "examples": [], "kirmse_walk_examples": [],
                     "kirmse_line_tree_examples": [], "saddle_fork_examples": []}
    for rec in kirmse.itertuples(index=False):
        cell = first(rec.row, rec.col)
        if cell not in o.index:
            continue
        out["matched"] += 1
        mine = o.loc[cell]
        for kind in ("line_parent", "prominence_parent"):
            theirs = first(getattr(rec, f"{kind}_row"), getattr(rec, f"{kind}_col"))
            ours_cell = (int(mine[f"{kind}_row"]), int(mine[f"{kind}_col"]))
            if theirs == ours_cell:
                out[kind]["agree"] += 1
                continue
            chain = _walk(o, cell, {theirs, ours_cell})
            kchain = _walk(kk, (rec.row, rec.col), {theirs, ours_cell}) if (rec.row, rec.col) in kk.index else []
            heights = [z_ft[c] for c in chain]
            kheights = [z_ft[c] for c in kchain]
            tie = len(set(heights)) < len(heights) or len(set(kheights)) < len(kheights)
            if kind == "prominence_parent" and ours_cell in o.index:
                # equal prominences: orokit counts the higher peak as more prominent, Kirmse's
                # compute_parents needs a strictly larger prominence
                tie = tie or bool(np.rint(o.at[ours_cell, "prominence"] / FT) == np.rint(mine["prominence"] / FT))
            flat = any(_is_flat_summit(z_ft, *c) for c in (theirs, ours_cell) if c[0] >= 0)
            h, w = z_ft.shape
            on_edge = [c for c in chain + kchain + [(int(mine["saddle_row"]), int(mine["saddle_col"]))]
                       if c[0] >= 0 and (c[0] in (0, h - 1) or c[1] in (0, w - 1))]
            walk_on_his = kw.get(cell) if kw is not None else None
            his_walk = walk_on_his[0 if kind == "line_parent" else 1] if walk_on_his else None
            if tie or flat:
                out[kind]["tie"] += 1
            elif his_walk == ours_cell:
                out[kind]["kirmse_line_tree"] += 1
                if len(out[kind]["kirmse_line_tree_examples"]) < 5:
                    out[kind]["kirmse_line_tree_examples"].append({"peak": cell, "kirmse": theirs, "orokit": ours_cell})
            elif on_edge:
                out[kind]["edge"] += 1
            elif tree is not None and (_key_saddle_tie(z_ft, tree, cell, theirs, ours_cell)
                                       or _key_saddles_differ_at_one_level(z_ft, rec, mine)):
                out[kind]["key_saddle_tie"] += 1
            elif tree is not None and _walk_diverges(z_ft, tree, cell, theirs, ours_cell,
                                                     (int(mine["saddle_row"]), int(mine["saddle_col"]))):
                out[kind]["kirmse_walk"] += 1
                if len(out[kind]["kirmse_walk_examples"]) < 5:
                    out[kind]["kirmse_walk_examples"].append({"peak": cell, "kirmse": theirs, "orokit": ours_cell})
            elif tree is not None and _walk_forks(z_ft, tree, cell, theirs, ours_cell,
                                                  (int(mine["saddle_row"]), int(mine["saddle_col"]))):
                out[kind]["saddle_fork"] += 1
                if len(out[kind]["saddle_fork_examples"]) < 5:
                    out[kind]["saddle_fork_examples"].append({"peak": cell, "kirmse": theirs, "orokit": ours_cell})
            else:
                out[kind]["unexplained"] += 1
                if len(out[kind]["examples"]) < 5:
                    out[kind]["examples"].append({"peak": cell, "kirmse": theirs, "orokit": ours_cell,
                                                  "walk_on_kirmse_tree": his_walk})
    return out


def _walk(o: pd.DataFrame, start: tuple[int, int], targets: set) -> list[tuple[int, int]]:
    """``start`` and its chain of line parents in ``o``, up to the last of ``targets`` met."""
    chain, last, cell = [start], 1, start
    while True:
        nxt = (int(o.at[cell, "line_parent_row"]), int(o.at[cell, "line_parent_col"]))
        if nxt[0] < 0 or nxt not in o.index or nxt in chain:
            break
        chain.append(nxt)
        if nxt in targets:
            last = len(chain)
        cell = nxt
    return chain[:max(last, 2) if len(chain) > 1 else 1]


def _is_flat_summit(z: np.ndarray, r: int, c: int) -> bool:
    """True when a neighbour of (r, c) has the same elevation (a flat summit)."""
    win = z[max(r - 1, 0):r + 2, max(c - 1, 0):c + 2]
    return int((win == z[r, c]).sum()) > 1


_RING = [(dr, dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1) if (dr, dc) != (0, 0)]


def _flat_area(z: np.ndarray, cell: tuple[int, int]) -> tuple[list, list]:
    """The 8-connected equal-elevation area of ``cell`` and the higher cells around it."""
    h, w = z.shape
    v = z[cell]
    area, seen, stack, higher = [], {cell}, [cell], set()
    while stack:
        r, c = stack.pop()
        area.append((r, c))
        for dr, dc in _RING:
            n = (r + dr, c + dc)
            if not (0 <= n[0] < h and 0 <= n[1] < w) or np.isnan(z[n]):
                continue
            if z[n] == v and n not in seen:
                seen.add(n)
                stack.append(n)
            elif z[n] > v:
                higher.add(n)
    return area, sorted(higher, reverse=True)  # Kirmse's order: his raster order is ours reversed (half turn)


def _segments(higher: list) -> list[list]:
    """8-connected groups of the higher cells around a flat area, in Kirmse's discovery order."""
    left, out = list(higher), []
    while left:
        seg, stack = [], [left.pop(0)]
        while stack:
            p = stack.pop()
            seg.append(p)
            nb = [q for q in left if abs(q[0] - p[0]) <= 1 and abs(q[1] - p[1]) <= 1]
            for q in nb:
                left.remove(q)
            stack.extend(nb)
        out.append(seg)
    return out


def _highest(z: np.ndarray, cells: list) -> tuple[int, int]:
    """Highest cell; among equal ones the first in Kirmse's order (the largest flat index here)."""
    return max(cells, key=lambda c: (z[c], c))


def kirmse_walk_up(z: np.ndarray, start: tuple[int, int], *, saddle_exit: bool = True) -> tuple[int, int]:
    """The peak (first cell of its flat summit) an uphill walk from ``start`` reaches, by the rules
    of Kirmse's ``TreeBuilder::walkUpToPeak`` (read in ../shared/baselines/mountains/code/tree_builder.cpp):
    the highest cell of the 3 x 3 window; on a flat area without a higher neighbour, its highest
    boundary cell; and (``saddle_exit``) on a cell whose flat area is a saddle (two or more
    8-connected groups of higher cells around it), the highest cell of the first group that is not
    the highest one (his ``rise1``), whatever the direction the walk came from. Without
    ``saddle_exit`` it is the plain steepest ascent the tree builder's comment describes.
    """
    cell = start
    for _ in range(z.size):
        area, higher = _flat_area(z, cell)
        if not higher:
            return min(area)
        if saddle_exit:
            segs = _segments(higher)
            if len(segs) >= 2:
                tops = [_highest(z, g) for g in segs]
                best = max(range(len(tops)), key=lambda i: (z[tops[i]], -i))
                cell = tops[next(i for i in range(len(tops)) if i != best)]
                continue
        r, c = cell
        win = [(r + dr, c + dc) for dr, dc in _RING if 0 <= r + dr < z.shape[0] and 0 <= c + dc < z.shape[1]
               and not np.isnan(z[r + dr, c + dc])]
        nxt = _highest(z, win)
        cell = nxt if z[nxt] > z[cell] else _highest(z, higher)
    raise RuntimeError(f"no peak reached from {start}")


def orokit_walk_up(z: np.ndarray, start: tuple[int, int]) -> tuple[int, int]:
    """The peak (first cell of its flat summit) orokit's steepest ascent reaches from ``start``:
    the highest 8-neighbour in the total order (elevation, then the earlier cell in raster order)
    while it is above the current cell in that order."""
    h, w = z.shape
    cell = start
    for _ in range(z.size):
        r, c = cell
        best = cell
        for dr, dc in _RING:
            n = (r + dr, c + dc)
            if 0 <= n[0] < h and 0 <= n[1] < w and not np.isnan(z[n]) and (
                    z[n] > z[best] or (z[n] == z[best] and n < best)):
                best = n
        if best == cell:
            return min(_flat_area(z, cell)[0])
        cell = best
    raise RuntimeError(f"no peak reached from {start}")


def saddle_exit_divergence(z: np.ndarray, saddle: tuple[int, int]) -> bool:
    """True when, from some rise of ``saddle``'s flat area (the highest cell of a group of higher
    cells around it), Kirmse's walk (:func:`kirmse_walk_up`) and orokit's steepest ascent
    (:func:`orokit_walk_up`) reach different peaks: the two divide trees then tie the saddle to
    different peaks. Two rules of his walk cause it: leaving an intermediate saddle by its first
    rise, and taking the *last* of equal highest neighbours in our raster order (the half turn that
    aligns flat summits reverses his neighbour scan), where orokit takes the first."""
    _, higher = _flat_area(z, saddle)
    for seg in _segments(higher):
        top = _highest(z, seg)
        if kirmse_walk_up(z, top) != orokit_walk_up(z, top):
            return True
    return False


def saddle_fork(z: np.ndarray, saddle: tuple[int, int]) -> bool:
    """True when the steepest ascent (:func:`orokit_walk_up`) from the cells just above ``saddle``'s
    flat area (every higher 8-neighbour, not one per group) reaches three or more peaks: the saddle
    joins P's side to two peaks of a part that is already connected above it, so the ridge beyond
    the saddle forks at the saddle cell itself. Both trees are valid maximum spanning trees; orokit
    takes the branch whose kept end is highest (:func:`orokit.topology._kernels.prune_edges`),
    Kirmse the one his walk from the saddle reaches."""
    _, higher = _flat_area(z, saddle)
    return len({orokit_walk_up(z, c) for c in higher}) >= 3


def _key_saddle_tie(z: np.ndarray, tree, p: tuple[int, int], theirs: tuple[int, int],
                    ours: tuple[int, int]) -> bool:
    """True when the lowest saddles on the two walks (orokit's unpruned tree, P to each parent) are
    different cells of the same elevation: P has two equally low ways to higher ground, so its key
    saddle, and the side the walk takes, is a tie between them."""
    if ours[0] < 0 or theirs[0] < 0:
        return False
    a, b = tree_path_saddles(tree, p, ours), tree_path_saddles(tree, p, theirs)
    if not a or not b:
        return False
    la, lb = min(a, key=lambda c: z[c]), min(b, key=lambda c: z[c])
    return bool(z[la] == z[lb] and la != lb)


def _key_saddles_differ_at_one_level(z: np.ndarray, rec, mine) -> bool:
    """True when Kirmse's key saddle of P (his ``compute_parents`` column) and orokit's are different
    cells of the same elevation: two equally low saddles join P to higher ground and each tree keeps
    one of them (which one is a tie in the saddle order)."""
    theirs = (int(getattr(rec, "saddle_row", -1)), int(getattr(rec, "saddle_col", -1)))
    ours = (int(mine["saddle_row"]), int(mine["saddle_col"]))
    return theirs[0] >= 0 and ours[0] >= 0 and theirs != ours and bool(z[theirs] == z[ours])


def _walk_saddles(tree, p: tuple[int, int], theirs: tuple[int, int], ours: tuple[int, int],
                  key_saddle: tuple[int, int]) -> set[tuple[int, int]]:
    """The saddles where the two walks (P to orokit's parent, P to Kirmse's, on orokit's unpruned
    tree) have not parted yet: P's key saddle, the saddles of their common part and the first
    saddle of each branch."""
    a = tree_path_saddles(tree, p, ours) if ours[0] >= 0 else []
    b = tree_path_saddles(tree, p, theirs) if theirs[0] >= 0 else []
    common = 0
    while common < min(len(a), len(b)) and a[common] == b[common]:
        common += 1
    cand = {key_saddle} if key_saddle[0] >= 0 else set()
    cand.update(a[:common + 1])
    cand.update(b[:common + 1])
    return cand


def _walk_diverges(z: np.ndarray, tree, p: tuple[int, int], theirs: tuple[int, int], ours: tuple[int, int],
                   key_saddle: tuple[int, int]) -> bool:
    """True when Kirmse's uphill walk leaves the steepest ascent at one of :func:`_walk_saddles`."""
    return any(saddle_exit_divergence(z, s) for s in _walk_saddles(tree, p, theirs, ours, key_saddle))


def _walk_forks(z: np.ndarray, tree, p: tuple[int, int], theirs: tuple[int, int], ours: tuple[int, int],
                key_saddle: tuple[int, int]) -> bool:
    """True when one of :func:`_walk_saddles` is a :func:`saddle_fork`."""
    return any(saddle_fork(z, s) for s in _walk_saddles(tree, p, theirs, ours, key_saddle))


def tree_path_saddles(tree, a: tuple[int, int], b: tuple[int, int]) -> list[tuple[int, int]]:
    """Saddle cells on the path between peaks ``a`` and ``b`` of a Divide Tree (empty if none)."""
    pk, sd, e = tree.peaks, tree.saddles, tree.edges
    key = {(int(r), int(c)): i for i, (r, c) in enumerate(zip(pk["row"], pk["col"]))}
    if a not in key or b not in key:
        return []
    adj: dict[int, list] = {}
    for x, y, s in zip(e["peak_a"], e["peak_b"], e["saddle"]):
        adj.setdefault(int(x), []).append((int(y), int(s)))
        adj.setdefault(int(y), []).append((int(x), int(s)))
    prev = {key[a]: None}
    stack = [key[a]]
    while stack:
        u = stack.pop()
        for v, s in adj.get(u, []):
            if v not in prev:
                prev[v] = (u, s)
                stack.append(v)
    out, u = [], key[b]
    if u not in prev:
        return []
    while prev[u] is not None:
        u, s = prev[u]
        out.append((int(sd["row"].iloc[s]), int(sd["col"].iloc[s])))
    return out[::-1]  # from a


def unpruned_analysis(tif: Path):
    """orokit's analysis of ``tif`` at threshold 0 (every peak; its tree is the unpruned Divide Tree)."""
    import orokit
    from orokit.io.dem import read_dem

    return orokit.analyze(read_dem(tif), min_prominence_m=0.0, isolation=False)


def unpruned_walk_check(tif: Path, ours: pd.DataFrame, eps_m: float, full=None) -> dict:
    """orokit's parents on the tree pruned at ``eps_m`` against the walk on the *unpruned* tree.

    On the tree of every peak (threshold 0), follow the chain of line parents from P: the
    line parent among the kept peaks is the first peak on it with prominence >= eps, the
    prominence parent the first more prominent than P. Returns the number of kept peaks
    whose pruned-tree parents differ (0 when pruning does not change the walk). ``full``:
    :func:`unpruned_analysis` of ``tif`` if already done.
    """
    full = (full if full is not None else unpruned_analysis(tif)).peaks
    cell = list(zip(full["row"].tolist(), full["col"].tolist()))
    lp = dict(zip(cell, zip(full["line_parent_row"].tolist(), full["line_parent_col"].tolist())))
    prom = dict(zip(cell, full["prominence"].tolist()))
    elev = dict(zip(cell, full["elevation"].tolist()))
    out = {"unpruned_peaks": len(full), "line_parent_differs": 0, "prominence_parent_differs": 0}
    for rec in ours.itertuples(index=False):
        p = (rec.row, rec.col)
        want_line = want_prom = (-1, -1)
        cur = p
        while True:
            cur = lp.get(cur, (-1, -1))
            if cur[0] < 0:
                break
            if want_line[0] < 0 and prom[cur] >= eps_m:
                want_line = cur
            if prom[cur] > prom[p] or (prom[cur] == prom[p] and elev[cur] > elev[p]):
                want_prom = cur
                break
        out["line_parent_differs"] += want_line != (rec.line_parent_row, rec.line_parent_col)
        out["prominence_parent_differs"] += want_prom != (rec.prominence_parent_row, rec.prominence_parent_col)
    return out


def run(name: str, bin_dir: Path, work: Path, eps_ft: float) -> dict:
    z_ft = dem_feet(name)
    folder = work / Path(name).stem
    s = write_kirmse_tile(z_ft, folder / "tiles")
    tif = write_geotiff_m(z_ft, folder / "dem.tif")
    out = folder / "kirmse"
    out.mkdir(parents=True, exist_ok=True)
    for cmd in kirmse_commands(bin_dir, folder / "tiles", out, s, eps_ft):
        timed(cmd)
    dvt = sorted(out.glob("results*.dvt"))
    if len(dvt) != 1:
        raise RuntimeError(f"expected one merged tree results*.dvt in {out}, found {dvt}")
    subprocess.run([str(bin_dir / "compute_parents"), "-m", repr(eps_ft / SCALE), str(dvt[0]),
                    str(out / "parents.txt")], check=True, capture_output=True, text=True)
    reroot_kirmse_tree(dvt[0], out / "rerooted.dvt")
    subprocess.run([str(bin_dir / "compute_parents"), "-m", repr(eps_ft / SCALE), str(out / "rerooted.dvt"),
                    str(out / "parents_rerooted.txt")], check=True, capture_output=True, text=True)
    subprocess.run(orokit_command(tif, folder / "orokit", isolation=False, eps_ft=eps_ft), check=True,
                   capture_output=True, text=True)
    ours = pd.read_parquet(folder / "orokit" / "peaks.parquet",
                           columns=["row", "col", "elevation", "prominence", "saddle_row", "saddle_col", "line_parent_row", "line_parent_col",
                                    "prominence_parent_row", "prominence_parent_col"])
    full = unpruned_analysis(tif)
    res = compare(kirmse_parents(out / "parents.txt", s, z_ft.shape), ours, z_ft, full.tree,
                  kirmse_tree_walk(dvt[0], z_ft.shape))
    rr = compare(kirmse_parents(out / "parents_rerooted.txt", s, z_ft.shape), ours, z_ft)
    res["kirmse_rerooted_agree"] = {k: rr[k]["agree"] for k in ("line_parent", "prominence_parent")}
    res["orokit_vs_unpruned_walk"] = unpruned_walk_check(tif, ours, eps_ft * FT, full)
    res["dem"] = name
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dems", nargs="+", default=DATASETS, help="dataset names or raster files")
    ap.add_argument("--kirmse-bin", type=Path, default=None, help="folder of already built Kirmse binaries")
    ap.add_argument("--workdir", type=Path, default=None)
    ap.add_argument("--min-prominence-ft", type=float, default=EPS_FT)
    ap.add_argument("--no-record", action="store_true")
    a = ap.parse_args()
    tmp = tempfile.TemporaryDirectory(prefix="orokit-parents-") if a.workdir is None else None
    work = Path(tmp.name) if tmp else a.workdir
    try:
        bin_dir = a.kirmse_bin or build_kirmse(work)
        rows = []
        print(f"{'dem':<20} {'peaks K/o':>11} {'matched':>7}  line parent agree/tie/ltree/edge/stie/walk/fork/other  "
              "prominence parent agree/tie/ltree/edge/stie/walk/fork/other")
        for name in a.dems:
            r = run(name, bin_dir, work, a.min_prominence_ft)
            rows.append(r)
            lp, pp = r["line_parent"], r["prominence_parent"]
            print(f"{r['dem']:<20} {r['kirmse_peaks']:>5}/{r['orokit_peaks']:<5} {r['matched']:>7}  "
                  f"{lp['agree']:>6}/{lp['tie']:>3}/{lp['kirmse_line_tree']:>3}/{lp['edge']:>3}/{lp['key_saddle_tie']:>3}/"
                  f"{lp['kirmse_walk']:>3}/{lp['saddle_fork']:>3}/{lp['unexplained']:<4}       "
                  f"{pp['agree']:>6}/{pp['tie']:>3}/{pp['kirmse_line_tree']:>3}/{pp['edge']:>3}/{pp['key_saddle_tie']:>3}/"
                  f"{pp['kirmse_walk']:>3}/{pp['saddle_fork']:>3}/{pp['unexplained']:<4}")
            ra = r["kirmse_rerooted_agree"]
            print(f"{'':<20} Kirmse's compute_parents on his tree rooted at its highest peak: agree "
                  f"{ra['line_parent']} line / {ra['prominence_parent']} prominence parents")
            u = r["orokit_vs_unpruned_walk"]
            print(f"{'':<20} orokit vs the walk on its unpruned tree ({u['unpruned_peaks']} peaks): "
                  f"{u['line_parent_differs']} line / {u['prominence_parent_differs']} prominence parents differ")
            for kind in ("line_parent", "prominence_parent"):
                for ex in r[kind]["examples"]:
                    print(f"    {kind} differs: {ex}")
        if not a.no_record:
            from _record import record

            print(f"recorded in {record('parents_vs_kirmse', {'eps_ft': a.min_prominence_ft, 'dems': rows})}")
    finally:
        if tmp is not None:
            tmp.cleanup()


if __name__ == "__main__":
    main()
