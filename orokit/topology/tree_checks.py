"""The one validation of a Divide Tree read from a file.

Every reader (reference TXT, GeoPackage, the ``read_divide_tree`` dispatcher) calls
:func:`check_read_tree`, so every command refuses the same malformed files with the
same messages: the file is named and its own ids are quoted (1-based ``id`` column of
a TXT file, ``peak_id``/``saddle_id`` of a GeoPackage).
"""
from __future__ import annotations

import numpy as np

from orokit.errors import DivideTreeError
from orokit.topology.divide_tree import DivideTree

__all__ = ["check_read_tree"]


def _labels(frame, column: str | None) -> np.ndarray:
    if column is not None and column in frame.columns:
        return frame[column].to_numpy()
    return np.arange(len(frame))


def check_read_tree(tree: DivideTree, source: str, *, id_column: str | None = None) -> DivideTree:
    """Return ``tree`` if it is a valid Divide Tree, else raise :class:`DivideTreeError`.

    Checks: finite coordinates and elevations; ridge ids in range; no ridge from a
    peak to itself; no cycle (at most n - 1 ridges, no ridge joining two peaks already
    connected); every saddle at or below both peaks of each of its ridges.

    Parameters
    ----------
    tree
        The tree as read (positional ids in ``edges``).
    source
        The file, quoted in every message.
    id_column
        Column of ``peaks``/``saddles`` holding the file's own ids (``"txt_id"``);
        ``None`` quotes the positional ids (the GeoPackage ``peak_id``/``saddle_id``).
    """
    pid, sid = _labels(tree.peaks, id_column), _labels(tree.saddles, id_column)
    what = "id" if id_column is not None else "peak_id/saddle_id"
    for name, frame, ids in (("peak", tree.peaks, pid), ("saddle", tree.saddles, sid)):
        for col in ("x", "y", "elevation"):
            if col not in frame.columns:
                raise DivideTreeError(f"{source}: the {name}s have no {col!r} column")
            v = frame[col].to_numpy(float)
            bad = np.flatnonzero(~np.isfinite(v))
            if bad.size:
                raise DivideTreeError(f"{source}: {name} {ids[bad[0]]} has {col} {v[bad[0]]} ({bad.size} {name}(s) "
                                      f"without a finite {col}); every {name} needs x, y and elevation")
    e = tree.edges
    a, b, s = (e[c].to_numpy() for c in ("peak_a", "peak_b", "saddle"))
    n, m = tree.n_peaks, tree.n_saddles
    for i in range(a.size):
        if not (0 <= a[i] < n and 0 <= b[i] < n and 0 <= s[i] < m):
            raise DivideTreeError(f"{source}: ridge {i + 1} refers to a peak or saddle that does not exist "
                                  f"({n} peaks, {m} saddles)")
    if a.size >= max(n, 1):
        raise DivideTreeError(f"{source}: {a.size} ridges for {n} peaks; a Divide Tree has at most peaks - 1 ridges")
    pz = tree.peaks["elevation"].to_numpy(float)
    sz = tree.saddles["elevation"].to_numpy(float)
    root = np.arange(n)

    def find(x: int) -> int:
        while root[x] != x:
            root[x] = root[root[x]]
            x = root[x]
        return x

    for i in range(a.size):
        pa, pb, sd = int(a[i]), int(b[i]), int(s[i])
        if pa == pb:
            raise DivideTreeError(f"{source}: ridge {i + 1} joins peak {pid[pa]} to itself")
        if sz[sd] > pz[pa] or sz[sd] > pz[pb]:
            raise DivideTreeError(
                f"{source}: saddle {sid[sd]} ({sz[sd]:.2f} m) is above a peak of its ridge {i + 1} "
                f"(peak {pid[pa]}: {pz[pa]:.2f} m, peak {pid[pb]}: {pz[pb]:.2f} m); a saddle lies at or below "
                f"both peaks it joins (ids are the file's {what})"
            )
        ra, rb = find(pa), find(pb)
        if ra == rb:
            raise DivideTreeError(f"{source}: ridge {i + 1} (peaks {pid[pa]} and {pid[pb]}, saddle {sid[sd]}) closes a "
                                  f"cycle; a Divide Tree has none (ids are the file's {what})")
        root[rb] = ra
    return tree
