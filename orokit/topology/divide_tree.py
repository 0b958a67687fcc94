"""The Divide Tree: peaks linked through saddles along ridges.

A Divide Tree is the maximum spanning tree of the peak-saddle (ridge) network: every
ridge joins two peaks through one saddle, and the saddle is the highest pass between
them. It holds everything needed to compute prominence (elder rule), and it can be
pruned at a prominence threshold without changing any surviving peak's prominence.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from orokit.errors import DivideTreeError

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["DivideTree"]

_EDGE_COLUMNS = ["peak_a", "peak_b", "saddle"]


@dataclass(frozen=True)
class DivideTree:
    """Peaks, saddles and ridges (edges ``peak_a -- saddle -- peak_b``).

    Attributes
    ----------
    peaks : DataFrame indexed 0..n-1 with columns ``x``, ``y``, ``elevation`` (metres)
        and optionally ``row``, ``col`` (raster cell) and any other per-peak column.
    saddles : DataFrame indexed 0..m-1, columns ``x``, ``y``, ``elevation`` (and
        optionally ``row``, ``col``).
    edges : DataFrame with integer columns ``peak_a``, ``peak_b``, ``saddle``
        (positional ids), one row per ridge.
    crs : pyproj CRS of x/y, or None for an unknown/local frame.
    attrs : free metadata (units, thresholds, provenance).

    Notes
    -----
    Ties are broken deterministically: among equal elevations the lower id counts as
    higher (for trees computed from a raster, ids follow raster order, so this is the
    same "first cell in raster order wins" rule as the raster engine).
    """

    peaks: pd.DataFrame
    saddles: pd.DataFrame
    edges: pd.DataFrame
    crs: Any = None
    attrs: dict = field(default_factory=dict)

    # ------------------------------------------------------------------ basics
    @property
    def n_peaks(self) -> int:
        return len(self.peaks)

    @property
    def n_saddles(self) -> int:
        return len(self.saddles)

    def __post_init__(self) -> None:
        for name, frame in (("peaks", self.peaks), ("saddles", self.saddles)):
            missing = {"x", "y", "elevation"} - set(frame.columns)
            if missing:
                raise DivideTreeError(f"DivideTree.{name} lacks columns {sorted(missing)}")
        missing = set(_EDGE_COLUMNS) - set(self.edges.columns)
        if missing:
            raise DivideTreeError(f"DivideTree.edges lacks columns {sorted(missing)}")

    @classmethod
    def from_arrays(
        cls,
        peak_xyz: np.ndarray,
        saddle_xyz: np.ndarray,
        edges: np.ndarray,
        *,
        crs: Any = None,
        attrs: dict | None = None,
    ) -> "DivideTree":
        """Build a tree from (n, 3) peak and (m, 3) saddle arrays and (k, 3) edges."""
        peak_xyz = np.asarray(peak_xyz, dtype=float).reshape(-1, 3)
        saddle_xyz = np.asarray(saddle_xyz, dtype=float).reshape(-1, 3)
        import pandas as pd

        edges = np.asarray(edges, dtype=np.int64).reshape(-1, 3)
        peaks = pd.DataFrame(peak_xyz, columns=["x", "y", "elevation"])
        saddles = pd.DataFrame(saddle_xyz, columns=["x", "y", "elevation"])
        return cls(peaks, saddles, pd.DataFrame(edges, columns=_EDGE_COLUMNS), crs, dict(attrs or {}))

    def _edge_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        e = self.edges
        return (
            e["peak_a"].to_numpy(np.int64),
            e["peak_b"].to_numpy(np.int64),
            e["saddle"].to_numpy(np.int64),
        )

    def _sorted_edges(self) -> np.ndarray:
        """Edge order from the highest to the lowest saddle (ties: lower saddle id first)."""
        _, _, s = self._edge_arrays()
        sz = self.saddles["elevation"].to_numpy(float)[s]
        return np.lexsort((s, -sz))

    # -------------------------------------------------------------- prominence
    def prominence_table(self) -> pd.DataFrame:
        """Prominence, key saddle and island parent of every peak (elder rule).

        Returns a DataFrame aligned with ``peaks.index`` with columns ``prominence``
        (metres), ``key_saddle`` (saddle id, -1 for the highest peak of each connected
        part of the tree, whose prominence is its elevation as in the paper) and
        ``island_parent`` (the highest peak on the other side of the key saddle, -1 for
        roots; see :meth:`parents` for the line and prominence parents).
        """
        self.validate(check_elevations=False)
        a, b, s = self._edge_arrays()
        order = self._sorted_edges()
        pz = self.peaks["elevation"].to_numpy(float)
        sz = self.saddles["elevation"].to_numpy(float)
        keys = np.arange(self.n_peaks, dtype=np.int64)
        from orokit.topology import _kernels  # numba: imported when first used
        _, key_edge, parent, _ = _kernels.kruskal_sweep(
            pz, keys, a[order], b[order], sz[s[order]], s[order], np.full(self.n_peaks, -np.inf)
        )
        has = key_edge >= 0
        key_saddle = np.full(self.n_peaks, -1, np.int64)
        key_saddle[has] = s[order][key_edge[has]]
        prom = pz.copy()
        prom[has] = pz[has] - sz[key_saddle[has]]
        import pandas as pd

        return pd.DataFrame(
            {"prominence": prom, "key_saddle": key_saddle, "island_parent": parent}, index=self.peaks.index
        )

    def prominence(self) -> np.ndarray:
        """Prominence of every peak in metres (see :meth:`prominence_table`)."""
        return self.prominence_table()["prominence"].to_numpy()

    def parents(self, table: pd.DataFrame | None = None) -> pd.DataFrame:
        """Line parent and prominence parent of every peak of the tree.

        Walk from a peak P down to its key saddle and up the ridge on the other side,
        staying as high as possible: at each peak of the walk that is not yet higher
        than P, leave through that peak's own key saddle (towards its higher ground).

        - ``line_parent``: the first peak *higher* than P met on that walk;
        - ``prominence_parent``: the first peak *more prominent* than P met on it (the
          walk goes on through the line parents of the line parents).

        Both are -1 for the highest peak of each connected part of the tree (a landmass
        high point). Ties follow the tree's order: among equal elevations the lower id
        counts as higher, and among equal prominences the higher peak counts as more
        prominent; a landmass high point counts as more prominent than every other
        peak of its landmass. So both parents lie beyond P's key saddle, at or before
        the highest peak P meets there (its island parent), and the peaks between P
        and either parent on the walk are lower and less prominent than P.

        The parents are computed among the peaks *of this tree*: on a tree pruned at a
        threshold eps, the walk only meets peaks with prominence >= eps, so line
        parents (and, more rarely, prominence parents) depend on eps.

        Parameters
        ----------
        table : the tree's :meth:`prominence_table`, when already computed (only its
            ``prominence`` and the sign of ``key_saddle`` are read: the engine passes its own).

        Returns
        -------
        DataFrame aligned with ``peaks.index``: ``line_parent``, ``prominence_parent``
        (peak ids, -1 for none).

        Notes
        -----
        1. One Kruskal sweep over the ridges from the highest to the lowest saddle
           (ties: lower saddle id first, then ridge order). When two parts meet, the
           lower of their two tops gets its line parent: the first peak higher than it
           on the chain of line parents that starts at the ridge's end on the other
           side (that chain is the walk; every peak on it already has its line parent).
        2. Prominence parent: the first peak on the chain of line parents that is more
           prominent. No peak between two consecutive line parents can qualify (it is
           lower and its key saddle is higher).

        Examples
        --------
        A peak of 100 m joins, at a 50 m saddle, a 120 m peak that a 110 m saddle ties
        to a 200 m summit: its line parent is the 120 m peak (prominence 10 m), its
        prominence parent the summit.

        >>> t = DivideTree.from_arrays([[0, 0, 100], [2, 0, 120], [4, 0, 200]],
        ...                            [[1, 0, 50], [3, 0, 110]], [[0, 1, 0], [1, 2, 1]])
        >>> p = t.parents()
        >>> p["line_parent"].tolist(), p["prominence_parent"].tolist()
        ([1, 2, -1], [2, 2, -1])
        """
        if table is None:
            table = self.prominence_table()
        n = self.n_peaks
        a, b, _ = self._edge_arrays()
        order = self._sorted_edges()
        from orokit.topology import _kernels  # numba: imported when first used
        # the ridges' ends in the sweep's order, in the narrowest index type, gathered by blocks: no int64
        # copies beside the order, which goes before the sweep (16 bytes per ridge less at its top)
        index = _kernels.index_like(n, a.size).dtype
        ea, eb = np.empty(a.size, index), np.empty(a.size, index)
        for s0 in range(0, a.size, 1 << 18):
            o = order[s0:s0 + (1 << 18)]
            ea[s0:s0 + o.size], eb[s0:s0 + o.size] = a[o], b[o]
            del o  # a view of the order: none kept past the loop
        del order
        pz = self.peaks["elevation"].to_numpy(float)
        # larger = higher (ties: the lower id): np.lexsort((-np.arange(n), pz)), as one stable argsort of
        # the reversed elevations, without the two id arrays beside the sort (16 bytes per peak)
        by_z = np.argsort(pz[::-1], kind="stable")
        np.subtract(n - 1, by_z, out=by_z)
        rank = np.empty(n, np.int64)
        for s0 in range(0, n, 1 << 18):  # by blocks: no arange(n) beside the order and the ranks
            rank[by_z[s0:s0 + (1 << 18)]] = np.arange(s0, min(n, s0 + (1 << 18)))
        del by_z
        lp, _ = _kernels.line_parents(rank, ea, eb)
        del ea, eb
        prom = table["prominence"].to_numpy(float).copy()
        prom[table["key_saddle"].to_numpy() < 0] = np.inf
        pp = _kernels.first_ancestor_above(lp, prom, rank)
        import pandas as pd

        # copy=False: the two columns as made (a consolidated frame copied both: 16 bytes per peak beside them)
        return pd.DataFrame({"line_parent": lp, "prominence_parent": pp}, index=self.peaks.index, copy=False)

    # ----------------------------------------------------------------- pruning
    def prune(self, min_prominence_m: float) -> "DivideTree":
        """Keep the peaks with prominence >= ``min_prominence_m`` and rewire the ridges.

        Removed peaks are absorbed into the neighbour across their highest saddle, so
        the bottleneck (highest) saddle between any two kept peaks is unchanged and
        every kept peak keeps its prominence, key saddle and island parent. Roots (highest
        peak of each connected part) are kept when their elevation reaches the
        threshold. Saddles not used by the pruned ridges are dropped; ids are
        renumbered in their previous order.
        """
        table = self.prominence_table()
        keep = (table["prominence"].to_numpy() >= min_prominence_m)
        if min_prominence_m <= 0:
            # zero-prominence maxima are not peaks (flat shelves, plateau duplicates)
            keep &= (table["prominence"].to_numpy() > 0) | (table["key_saddle"].to_numpy() < 0)
        return self.subset(keep)

    def subset(self, keep: np.ndarray) -> "DivideTree":
        """Tree restricted to the peaks where ``keep`` is True (see :meth:`prune`)."""
        keep = np.asarray(keep, dtype=bool)
        a, b, s = self._edge_arrays()
        order = self._sorted_edges()
        sz = self.saddles["elevation"].to_numpy(float)[s[order]]
        inf = np.full(self.n_peaks, np.inf)
        pz = self.peaks["elevation"].to_numpy(float)
        ids = np.arange(self.n_peaks, dtype=np.int64)
        from orokit.topology import _kernels  # numba: imported when first used
        oa, ob, oe, _, _, _ = _kernels.prune_edges(
            self.n_peaks, a[order], b[order], sz, s[order], keep, -inf, inf, pz, ids, False, ids[:0]
        )
        new_id = np.full(self.n_peaks, -1, np.int64)
        new_id[keep] = np.arange(int(keep.sum()))
        saddle_ids = s[order][oe]
        saddle_sorted = np.unique(saddle_ids)
        new_saddle = np.full(self.n_saddles, -1, np.int64)
        new_saddle[saddle_sorted] = np.arange(saddle_sorted.size)
        import pandas as pd

        edges = pd.DataFrame(
            {"peak_a": new_id[oa], "peak_b": new_id[ob], "saddle": new_saddle[saddle_ids]}
        ).sort_values("saddle", kind="stable", ignore_index=True)
        return DivideTree(
            self.peaks[keep].reset_index(drop=True),
            self.saddles.iloc[saddle_sorted].reset_index(drop=True),
            edges,
            self.crs,
            dict(self.attrs),
        )

    # -------------------------------------------------------------- validation
    def validate(self, *, check_elevations: bool = True) -> None:
        """Raise :class:`DivideTreeError` unless the tree is well formed.

        Checks ids in range, no ridge from a peak to itself, no cycle, and
        (``check_elevations``) every saddle at or below both peaks it joins. A saddle
        may serve several ridges (a monkey saddle where three or more basins meet).
        """
        a, b, s = self._edge_arrays()
        n, m = self.n_peaks, self.n_saddles
        if a.size and (min(a.min(), b.min()) < 0 or max(a.max(), b.max()) >= n):
            raise DivideTreeError(f"ridge peak ids must lie in [0, {n}); got {a.min()}..{max(a.max(), b.max())}")
        if s.size and (s.min() < 0 or s.max() >= m):
            raise DivideTreeError(f"ridge saddle ids must lie in [0, {m}); got {s.min()}..{s.max()}")
        if np.any(a == b):
            raise DivideTreeError(f"ridge {int(np.flatnonzero(a == b)[0])} joins a peak to itself")
        if a.size >= max(n, 1):
            raise DivideTreeError(f"{a.size} ridges for {n} peaks: a tree has at most n - 1")
        if a.size:
            from orokit.topology._kernels import forest_components

            # n nodes and m edges without a cycle make exactly n - m components
            comp = forest_components(n, a, b)
            # counted by blocks: no arange(n) of the whole tree beside the components (8 bytes per peak)
            roots = sum(int(np.count_nonzero(comp[s0:s0 + (1 << 18)] == np.arange(s0, min(n, s0 + (1 << 18)))))
                        for s0 in range(0, n, 1 << 18))
            del comp
            if roots != n - a.size:  # find the first ridge that closes a cycle
                parent = np.arange(n)
                for i in range(a.size):
                    ra, rb = _find_py(parent, a[i]), _find_py(parent, b[i])
                    if ra == rb:
                        raise DivideTreeError(f"ridge {i} (peaks {a[i]}-{b[i]}) closes a cycle")
                    parent[rb] = ra
        if check_elevations and a.size:
            pz = self.peaks["elevation"].to_numpy(float)
            sz = self.saddles["elevation"].to_numpy(float)[s]
            bad = (sz > pz[a]) | (sz > pz[b])
            if bad.any():
                i = int(np.flatnonzero(bad)[0])
                raise DivideTreeError(
                    f"saddle {s[i]} ({sz[i]:.2f} m) is above a peak of its ridge "
                    f"({pz[a[i]]:.2f} m, {pz[b[i]]:.2f} m)"
                )

    # ---------------------------------------------------------------- geometry
    def ridges(self, start: int = 0, stop: int | None = None):
        """GeoDataFrame of ridge lines peak_a -> saddle -> peak_b (of the edges ``start:stop``)."""
        import geopandas as gpd
        from shapely import linestrings

        a, b, s = (v[start:stop] for v in self._edge_arrays())
        px, py = self.peaks["x"].to_numpy(float), self.peaks["y"].to_numpy(float)
        sx, sy = self.saddles["x"].to_numpy(float), self.saddles["y"].to_numpy(float)
        coords = np.stack(
            [np.stack([px[a], sx[s], px[b]], axis=1), np.stack([py[a], sy[s], py[b]], axis=1)], axis=2
        )
        geom = linestrings(coords) if len(a) else []
        frame = self.edges.iloc[start:stop].copy()
        frame["saddle_elevation"] = self.saddles["elevation"].to_numpy(float)[s]
        return gpd.GeoDataFrame(frame, geometry=geom, crs=self.crs)

    def points(self, which: str = "peaks"):
        """Peaks or saddles as a GeoDataFrame of points."""
        import geopandas as gpd

        frame = self.peaks if which == "peaks" else self.saddles
        geom = gpd.points_from_xy(frame["x"], frame["y"])
        return gpd.GeoDataFrame(frame.copy(), geometry=geom, crs=self.crs)

    def equals(self, other: "DivideTree") -> bool:
        """Same peaks, saddles and ridge set (ridge orientation and order ignored)."""
        if self.n_peaks != other.n_peaks or self.n_saddles != other.n_saddles:
            return False
        cols = ["x", "y", "elevation"]
        if not np.allclose(self.peaks[cols].to_numpy(float), other.peaks[cols].to_numpy(float), equal_nan=True):
            return False
        if not np.allclose(self.saddles[cols].to_numpy(float), other.saddles[cols].to_numpy(float), equal_nan=True):
            return False
        return _edge_set(self) == _edge_set(other)


def _edge_set(tree: DivideTree) -> set[tuple[int, int, int]]:
    a, b, s = tree._edge_arrays()
    return {(int(min(x, y)), int(max(x, y)), int(z)) for x, y, z in zip(a, b, s)}


def _find_py(parent: np.ndarray, x: int) -> int:
    while parent[x] != x:
        parent[x] = parent[parent[x]]
        x = parent[x]
    return x
