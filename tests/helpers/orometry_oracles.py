"""Independent oracles for the exact orometry engine (tests only).

Nothing here shares code or algorithm with ``orokit.topology``: peaks come from
plateau labelling, prominence from explicit floods of superlevel sets, persistence
from cripser, isolation from an exhaustive distance scan.

Conventions (the public contract of ``orokit.analyze``):

* 8-neighbourhood; NaN cells are nodata: they count as lower and never carry a path.
* A peak is an 8-connected plateau of equal valid cells whose valid neighbours are all
  strictly lower; it is reported at its first cell in raster order.
* Among equal-height peaks, the one whose representative cell comes first in raster
  order counts as higher.
* The highest peak of each 8-connected domain of valid cells is a root: prominence =
  elevation, no key saddle, parent -1.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage
from helpers.dems import build_dem

EIGHT = np.ones((3, 3), dtype=bool)


@dataclass
class OraclePeak:
    rep: int                    # flat index of the first plateau cell in raster order
    row: int
    col: int
    elevation: float
    cells: np.ndarray           # flat indices of the plateau
    saddle: float = np.nan      # key saddle elevation (NaN for roots)
    is_root: bool = False
    exact: bool = False         # prominence_exact under outside="unknown"
    component: np.ndarray | None = field(default=None, repr=False)  # {z >= saddle} component (bool grid)

    @property
    def prominence(self) -> float:
        return self.elevation if self.is_root else self.elevation - self.saddle


def make_dem(z, *, res=(10.0, 10.0), crs: str | None = "EPSG:32633", x0: float = 500000.0, y0: float = 5000000.0):
    """:func:`helpers.dems.build_dem` with 10 m cells and the corner ``(x0, y0)``
    (``crs=None``: a local grid with its corner at the origin)."""
    return build_dem(np.asarray(z), res=res, crs=crs, origin=None if crs is None else (x0, y0))


def plateau_peaks(z: np.ndarray) -> list[OraclePeak]:
    """Every peak of ``z`` (NaN = nodata), sorted by representative cell."""
    z = np.asarray(z, dtype=np.float64)
    valid = np.isfinite(z)
    peaks: list[OraclePeak] = []
    h, w = z.shape
    for v in np.unique(z[valid]):
        lab, n = ndimage.label(valid & (z == v), structure=EIGHT)
        for k in range(1, n + 1):
            mask = lab == k
            ring = ndimage.binary_dilation(mask, structure=EIGHT) & ~mask & valid
            if np.any(z[ring] >= v):
                continue
            cells = np.flatnonzero(mask)
            rep = int(cells.min())
            peaks.append(OraclePeak(rep, rep // w, rep % w, float(v), cells))
    peaks.sort(key=lambda p: p.rep)
    return peaks


def _outside_touch(valid: np.ndarray) -> np.ndarray:
    """Cells on the raster border or 8-adjacent to a NaN cell."""
    t = np.zeros_like(valid)
    t[0, :] = t[-1, :] = True
    t[:, 0] = t[:, -1] = True
    t |= ndimage.binary_dilation(~valid, structure=EIGHT)
    return t & valid


def brute_prominence(z: np.ndarray) -> list[OraclePeak]:
    """Peaks with key-saddle elevations found by flooding superlevel sets.

    For each peak P (height h) the higher ground is every cell above h plus the
    plateaus of equal-height peaks that come first in raster order. The key saddle is
    the highest level t such that P's 8-connected component of {z >= t} contains
    higher ground. A peak without higher ground in its domain is a root.
    """
    z = np.asarray(z, dtype=np.float64)
    valid = np.isfinite(z)
    peaks = plateau_peaks(z)
    if not peaks:
        return peaks
    flat = z.ravel()
    higher: list[np.ndarray] = []
    for p in peaks:
        hg = valid.ravel() & (flat > p.elevation)
        for q in peaks:
            if q.elevation == p.elevation and q.rep < p.rep:
                hg[q.cells] = True
        higher.append(hg)
    domains, _ = ndimage.label(valid, structure=EIGHT)
    dflat = domains.ravel()
    pending = []
    for p, hg in zip(peaks, higher):
        if hg[dflat == dflat[p.rep]].any():
            pending.append((p, hg))
        else:
            p.is_root = True
    touch = _outside_touch(valid).ravel()
    for t in np.unique(z[valid])[::-1]:
        if not pending:
            break
        lab = ndimage.label(valid & (z >= t), structure=EIGHT)[0].ravel()
        still = []
        for p, hg in pending:
            if t > p.elevation:
                still.append((p, hg))
                continue
            comp = lab == lab[p.rep]
            if (comp & hg).any():
                p.saddle = float(t)
                p.component = comp.reshape(z.shape)
                strict = ndimage.label(valid & (z > t), structure=EIGHT)[0].ravel()
                p.exact = not bool((touch & (strict == strict[p.rep])).any())
            else:
                still.append((p, hg))
        pending = still
    assert not pending, "oracle bug: a non-root peak never reached higher ground"
    return peaks


def n_domains(z: np.ndarray) -> int:
    return int(ndimage.label(np.isfinite(z), structure=EIGHT)[1])


def persistence_pairs(z: np.ndarray) -> tuple[list[tuple[float, float]], list[float]]:
    """0-dim persistence of the superlevel filtration with 8-connectivity (cripser).

    Returns (finite pairs (peak elevation, saddle elevation) with saddle < peak,
    elevations of the essential classes = one per domain). NaN cells enter the
    filtration after every valid cell, so components separated by nodata die there
    and are reported as essential.
    """
    import cripser

    z = np.asarray(z, dtype=np.float64)
    valid = np.isfinite(z)
    if not valid.any():
        return [], []
    span = float(np.nanmax(np.abs(z[valid]))) + 1.0
    big = 4.0 * span + 1e6
    f = np.where(valid, -z, big)
    if f.ndim == 2 and min(f.shape) == 1:
        f = f.reshape(-1)  # cripser wants a genuine 1-D array for 1 x N
    ph = cripser.compute_ph(f, filtration="T", maxdim=0)
    ph = ph[ph[:, 0] == 0]
    births, deaths = -ph[:, 1], ph[:, 2]
    finite_pairs, essential = [], []
    for b, d in zip(births, deaths):
        if -b >= big / 2:
            continue  # a nodata cell
        if not np.isfinite(d) or d >= big / 2:
            essential.append(float(b))
        elif -d < b:
            finite_pairs.append((float(b), float(-d)))
    return sorted(finite_pairs), sorted(essential)


def brute_isolation(z: np.ndarray, row: int, col: int, dx: float, dy: float) -> tuple[float, float, bool]:
    """(isolation, distance to the nearest outside/NaN cell, exact) of cell (row, col).

    Euclidean distance between cell centres with cell sizes dx (columns) and dy
    (rows). Isolation is NaN when no cell is strictly higher (then not exact).
    Outside cells are those just beyond the raster and the NaN cells.
    """
    z = np.asarray(z, dtype=np.float64)
    h, w = z.shape
    rr, cc = np.mgrid[0:h, 0:w]
    dist = np.hypot((rr - row) * dy, (cc - col) * dx)
    valid = np.isfinite(z)
    hi = valid & (z > z[row, col])
    iso = float(dist[hi].min()) if hi.any() else np.nan
    edge = min((row + 1) * dy, (h - row) * dy, (col + 1) * dx, (w - col) * dx)
    if (~valid).any():
        edge = min(edge, float(dist[~valid].min()))
    exact = bool(np.isfinite(iso) and iso < edge)
    return iso, edge, exact


def flat_domain_cells(z: np.ndarray) -> np.ndarray:
    """Boolean grid of the cells whose 8-connected domain holds a single value."""
    z = np.asarray(z, dtype=np.float64)
    valid = np.isfinite(z)
    lab, n = ndimage.label(valid, structure=EIGHT)
    out = np.zeros(z.shape, dtype=bool)
    for k in range(1, n + 1):
        m = lab == k
        if np.ptp(z[m]) == 0:
            out |= m
    return out


# ---------------------------------------------------------------- hypothesis strategies
def grids(max_side: int = 10, *, min_side: int = 1, nan: bool = True, max_levels: int = 5):
    """Small float32 grids with 2..max_levels distinct values (many ties) and NaN holes."""
    from hypothesis import strategies as st
    from hypothesis.extra.numpy import arrays

    @st.composite
    def build(draw):
        h = draw(st.integers(min_side, max_side))
        w = draw(st.integers(min_side, max_side))
        k = draw(st.integers(2, max_levels))
        levels = draw(
            st.lists(st.integers(-20, 60), min_size=k, max_size=k, unique=True)
            | st.lists(st.floats(-100, 3000, width=32, allow_subnormal=False), min_size=k, max_size=k, unique=True)
        )
        elements = st.sampled_from([float(v) for v in levels])
        z = draw(arrays(np.float32, (h, w), elements=elements))
        if nan and draw(st.booleans()):
            holes = draw(arrays(np.bool_, (h, w), elements=st.booleans()))
            if draw(st.booleans()):  # sparse holes most of the time
                holes &= draw(arrays(np.bool_, (h, w), elements=st.booleans()))
            z = z.copy()
            z[holes] = np.nan
        if not np.isfinite(z).any():
            z = z.copy()
            z[0, 0] = levels[0]
        return z

    return build()


def distinct_grids(max_side: int = 10):
    """Small float32 grids of distinct values (no ties at all)."""
    from hypothesis import strategies as st

    @st.composite
    def build(draw):
        h = draw(st.integers(1, max_side))
        w = draw(st.integers(1, max_side))
        seed = draw(st.integers(0, 2**32 - 1))
        rng = np.random.default_rng(seed)
        return (rng.permutation(h * w).reshape(h, w) * 1.5 + 10).astype(np.float32)

    return build()
