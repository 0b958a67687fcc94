"""Guérin 2016 backend: Sparse Construction Tree amplification from a learned dictionary.

E. Guérin, J. Digne, E. Galin, A. Peytavie, *Sparse representation of terrains for
procedural modeling*, Computer Graphics Forum 35(2), 2016 (doi:10.1111/cgf.12821).

A terrain is a blend of disk primitives of radius R centred on a grid of step R/2 (or R, ``step``):
``f = sum f_i a_i / sum a_i`` with ``a_i = (1 - r^2)^3`` (r = distance / R) and
``f_i = z_i + sum_j x_ij d_j``, where ``z_i`` is the patch mean and the ``x_i`` are sparse
codes (orthogonal matching pursuit, sparsity s) over a dictionary of zero-mean atoms.
For amplification the dictionary is a pair (H, L): H holds exemplar patches, L the same
patches block-averaged by the amplification factor; the coarse terrain is coded over L
and rebuilt with H (§5.3).

From a Divide Tree (orokit): the coarse terrain is the tree's ridges (linear from peak
to saddle) and rivers rasterised at L's cell (``factor`` x the working cell) and
interpolated linearly between them (``scipy.interpolate``); the exemplar is a real DEM.
Nothing is finer than the exemplar's cell: the synthesis runs at
``max(output cell, exemplar cell)`` and is resampled bicubically to a finer output grid.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field, replace

import numpy as np
import xarray as xr

from orokit.errors import InputError
from orokit.generators.base import as_dataarray, check_crs
from orokit.raster.rasterize import Grid

logger = logging.getLogger(__name__)

__all__ = ["GuerinParams", "Dictionary", "primitive_step", "build_dictionary", "sparse_codes", "synthesize", "amplify",
           "coarse_from_tree", "weight_kernel", "learn", "render", "resolve_max_detail", "TREE_MAX_DETAIL"]

_DICTIONARIES = ("complete", "constrained", "ksvd")
_STEPS = ("half-radius", "radius")


def primitive_step(radius: int, step: str = "half-radius") -> int:
    """Grid step (cells) of the primitives' centres: ``R/2`` (``half-radius``) or ``R`` (``radius``).

    >>> primitive_step(8), primitive_step(8, "radius")
    (4, 8)
    """
    if step not in _STEPS:
        raise InputError(f"step={step!r} is not one of {', '.join(_STEPS)}")
    return radius // 2 if step == "half-radius" else radius


@dataclass(frozen=True)
class GuerinParams:
    """Parameters of the Guérin 2016 backend (the paper's defaults where it gives them).

    radius : R, the primitives' radius in working cells (the paper: 8, 16 or 32); patches
        are ``2R x 2R`` squares (K = 4 R^2: 256 at R = 8, 1024 at R = 16, the paper's
        K ~ 10^3) on a grid of step R/2. orokit's default 8: on held-out halves of the
        norway DEM (8x, complete dictionary, s = 1) the slope distribution's W1 distance
        to the truth was 3.7 deg at R = 8, 4.6 at 16, 9.4 at 32, bicubic 4.2.
    factor : amplification factor: the coarse terrain's cell is ``factor`` working cells
        (the paper's L is H down-sampled; the issue's factor 8). ``2R`` must be a multiple.
    sparsity : s, atoms per primitive (the paper uses s = 1 for amplification).
    dictionary : ``complete`` (every exemplar primitive is an atom: N = n), ``constrained``
        (N atoms that are real exemplar patches, learned by the paper's problem 2) or
        ``ksvd`` (K-SVD on the joined (L, H) vectors, so the pairs stay in correspondence).
    n_atoms : N for the learned dictionaries (the paper: up to 10^4).
    iterations : learning iterations (constrained, ksvd).
    step : grid step of the primitives' centres: ``half-radius`` (R/2: the issue's and the
        paper's text, "the grid step is half the patch radius") or ``radius`` (R: what the
        paper's own count ``t0 = w h = n K / 4`` and its Table 1 storage ratios imply, n
        primitives of K = 4 R^2 samples); R/2 places 4 x as many primitives.
    max_detail : exemplar primitives whose detail (rms of the high patch minus its block
        means: what L cannot hold) exceeds ``max_detail`` x the rms of their zero-mean low
        patch are not atoms (orokit's rule; ``inf`` or 0 keeps every one, the paper). NaN
        (default): 1 when the coarse terrain is the tree's (ridges and rivers interpolated:
        smooth ramps), ``inf`` when it is a DEM (``coarse``). Why: an atom's high part is
        scaled by 1 / its low norm, so a nearly flat low patch with relief below the coarse
        cell, picked on a steep ramp, blows up. Ranking trees (seed 0, appalachians /
        karakoram / norway / sahara; landform targets met of 36): ``inf`` 14 (appalachians
        spanned -2560..2280 m for an exemplar of 298..1662 m), 4: 20, 2: 23, 1: 27, 0.5: 26.
        On a real coarse DEM (8x block means of a held-out half, slope W1 to the truth,
        norway / appalachians / karakoram) the rule costs detail: ``inf`` 3.77 / 4.42 /
        5.91 deg, 1: 5.02 / 6.44 / 7.14, bicubic 4.21 / 6.68 / 6.55. No effect at ``factor`` 1.
    coarse : a coarse DEM (file or manifest dataset) to amplify instead of the tree's
        interpolated ridges and rivers; read by the caller (CLI ``--param coarse=DEM.tif``,
        Python ``render_terrain(..., inputs={"coarse": dem})``).
    """

    radius: int = 8
    factor: int = 8
    sparsity: int = 1
    dictionary: str = field(default="complete", metadata={"choices": _DICTIONARIES})
    n_atoms: int = 1024
    iterations: int = 4
    step: str = field(default="half-radius", metadata={"choices": _STEPS})
    max_detail: float = float("nan")
    coarse: str = field(default="", metadata={"file": "dem"})

    def __post_init__(self) -> None:
        if not (isinstance(self.radius, int) and 2 <= self.radius <= 128 and self.radius % 2 == 0):
            raise InputError(f"radius must be an even number of cells in [2, 128], got {self.radius!r}")
        if not (isinstance(self.factor, int) and 1 <= self.factor <= 64):
            raise InputError(f"factor must be an integer in [1, 64], got {self.factor!r}")
        if (2 * self.radius) % self.factor:
            raise InputError(f"factor ({self.factor}) must divide the patch side 2 x radius ({2 * self.radius}); "
                             "e.g. radius=16 factor=8")
        if 2 * self.radius // self.factor < 2:
            raise InputError(f"the coarse patch (2 x radius / factor = {2 * self.radius // self.factor} cells a side) "
                             "must be at least 2 cells a side; raise radius or lower factor")
        if not (isinstance(self.sparsity, int) and self.sparsity >= 1):
            raise InputError(f"sparsity must be an integer >= 1, got {self.sparsity!r}")
        if self.sparsity > (2 * self.radius // self.factor) ** 2:
            raise InputError(f"sparsity ({self.sparsity}) exceeds the coarse patch size "
                             f"({(2 * self.radius // self.factor) ** 2} values); lower it or raise radius")
        if self.dictionary not in _DICTIONARIES:
            raise InputError(f"dictionary={self.dictionary!r} is not one of {', '.join(_DICTIONARIES)}")
        if not (isinstance(self.n_atoms, int) and 1 <= self.n_atoms <= 100_000):
            raise InputError(f"n_atoms must be an integer in [1, 100000], got {self.n_atoms!r}")
        if not (isinstance(self.iterations, int) and 0 <= self.iterations <= 100):
            raise InputError(f"iterations must be an integer in [0, 100], got {self.iterations!r}")
        if not (self.max_detail >= 0 or np.isnan(self.max_detail)):  # inf: no rule; NaN: from the coarse source
            raise InputError(f"max_detail must be a number >= 0 (0 or inf: keep every primitive), got {self.max_detail!r}")
        primitive_step(self.radius, self.step)  # refuses an unknown step


@dataclass(frozen=True)
class Dictionary:
    """A multi-resolution dictionary: ``low`` (N, k_L) atoms, zero-mean and L2-normalised,
    and ``high`` (N, 2R, 2R) their exemplar counterparts (zero-mean, same scale: the block
    average of ``high[j]`` by ``factor`` is ``low[j]``). ``source`` (N,) is the index of the
    exemplar primitive an atom was taken from (-1 for a K-SVD atom); ``step`` the grid step
    (cells) of the primitives it was learned from and that :func:`synthesize` uses."""

    low: np.ndarray
    high: np.ndarray
    source: np.ndarray
    radius: int
    factor: int
    step: int = 0

    def __post_init__(self) -> None:
        if self.step == 0:
            object.__setattr__(self, "step", self.radius // 2)

    @property
    def n_atoms(self) -> int:
        return int(self.low.shape[0])


def weight_kernel(radius: int) -> np.ndarray:
    """``(1 - r^2)^3`` on the ``2R x 2R`` cells of a patch (r = centre distance / R).

    >>> w = weight_kernel(4); w.shape, bool(w.min() > 0), float(w.max()) < 1
    ((8, 8), False, True)
    """
    c = np.arange(2 * radius) + 0.5 - radius
    r2 = (c[:, None] ** 2 + c[None, :] ** 2) / float(radius) ** 2
    return np.where(r2 < 1.0, (1.0 - r2) ** 3, 0.0)


def _centres(n: int, step: int) -> np.ndarray:
    """Primitive centres (cell-corner index) 0, step, ... up to the first one >= n."""
    return np.arange(0, n + step, step)


def _patches(padded: np.ndarray, pad: int, rows: np.ndarray, cols: np.ndarray, side: int, offset: int) -> np.ndarray:
    """Squares ``side x side`` whose top-left cell is at ``(r - offset, c - offset)`` of the
    unpadded array, for every ``r`` in rows and ``c`` in cols: (len(rows) * len(cols), side, side)."""
    from numpy.lib.stride_tricks import sliding_window_view

    win = sliding_window_view(padded, (side, side))
    return win[np.ix_(rows - offset + pad, cols - offset + pad)].reshape(-1, side, side)


def _block_mean(p: np.ndarray, f: int) -> np.ndarray:
    n, s, _ = p.shape
    return p.reshape(n, s // f, f, s // f, f).mean(axis=(2, 4))


def _pad(z: np.ndarray, pad: int) -> np.ndarray:
    # reflect needs pad < size; symmetric repeats as often as needed via np.pad's own loop
    return np.pad(z, pad, mode="symmetric")


def primitives(z: np.ndarray, radius: int, factor: int, step: int | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The primitives of a terrain ``z``: high ``(n, 2R, 2R)``, low ``(n, k_L)`` (block means),
    and their means ``(n,)``. Centres every ``step`` cells (default R/2); the terrain is
    mirrored at its borders. Patches holding nodata are NaN (callers drop them)."""
    step = radius // 2 if step is None else int(step)
    pad = 2 * radius
    zp = _pad(np.asarray(z, float), pad)
    rows, cols = _centres(z.shape[0], step), _centres(z.shape[1], step)
    high = _patches(zp, pad, rows, cols, 2 * radius, radius)
    low = _block_mean(high, factor).reshape(high.shape[0], -1)
    return high, low, low.mean(axis=1)


def _normalised_pairs(high: np.ndarray, low: np.ndarray, mean: np.ndarray, max_detail: float = float("inf")
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Zero-mean pairs scaled by the low atom's L2 norm; flat or nodata patches dropped, and
    those whose detail (rms of ``high`` minus its block means) exceeds ``max_detail`` x the
    rms of their zero-mean low patch."""
    lc = low - mean[:, None]
    norm = np.linalg.norm(lc, axis=1)
    ok = np.isfinite(norm) & (norm > 1e-9 * (1.0 + np.abs(mean))) & np.isfinite(high).all(axis=(1, 2))
    if np.isfinite(max_detail) and max_detail > 0:  # NaN (unresolved) keeps every primitive
        f = high.shape[1] // int(round(np.sqrt(low.shape[1])))
        up = np.repeat(np.repeat(low.reshape(-1, high.shape[1] // f, high.shape[2] // f), f, axis=1), f, axis=2)
        detail = np.sqrt(np.mean((high - up) ** 2, axis=(1, 2)))
        with np.errstate(invalid="ignore"):
            ok &= detail <= max_detail * norm / np.sqrt(low.shape[1])
    idx = np.flatnonzero(ok)
    s = norm[idx]
    return lc[idx] / s[:, None], (high[idx] - mean[idx, None, None]) / s[:, None, None], idx


def sparse_codes(low: np.ndarray, signals: np.ndarray, sparsity: int):
    """OMP codes of zero-mean ``signals`` (n, k_L) over the unit atoms ``low`` (N, k_L), as a
    ``scipy.sparse`` CSR matrix (n, N) with at most ``sparsity`` entries a row.

    At s = 1 the best atom is ``argmax |<d_j, y>|`` with coefficient ``<d_j, y>``: for short
    atoms (k_L <= 16) the nearest of the +-d_j to ``y / |y|`` (``scipy.spatial.cKDTree``;
    ``|u - d|^2 = 2 - 2 <u, d>``), else blocks of correlations. At s > 1 scikit-learn's
    ``orthogonal_mp_gram`` (N <= 4096) or ``orthogonal_mp``, by blocks of signals.
    """
    from scipy import sparse

    n, big = signals.shape[0], low.shape[0]
    if n == 0:
        return sparse.csr_matrix((0, big))
    if sparsity == 1 or big == 1:
        if low.shape[1] <= 16:
            from scipy.spatial import cKDTree

            norm = np.linalg.norm(signals, axis=1)
            u = signals / np.where(norm > 0, norm, 1.0)[:, None]
            _, j = cKDTree(np.concatenate([low, -low])).query(u)
            j = np.asarray(j) % big
        else:
            block = max(1, 4_000_000 // big)
            j = np.concatenate([np.abs(signals[b:b + block] @ low.T).argmax(axis=1) for b in range(0, n, block)])
        coef = np.einsum("ij,ij->i", signals, low[j])
        return sparse.csr_matrix((coef, (np.arange(n), j)), shape=(n, big))
    import warnings

    from sklearn.linear_model import orthogonal_mp, orthogonal_mp_gram

    s = min(sparsity, big, low.shape[1])
    block = max(1, 4_000_000 // big)
    parts = []
    with warnings.catch_warnings():  # exact fits before s atoms stop early: the codes are still right
        warnings.filterwarnings("ignore", message="Orthogonal matching pursuit ended prematurely")
        gram = low @ low.T if big <= 4096 else None
        for b in range(0, n, block):
            y = signals[b:b + block]
            if gram is not None:
                x = orthogonal_mp_gram(gram, low @ y.T, n_nonzero_coefs=s)
            else:
                x = orthogonal_mp(low.T, y.T, n_nonzero_coefs=s)
            parts.append(sparse.csr_matrix(np.asarray(x, float).reshape(big, -1).T))
    return sparse.vstack(parts, format="csr")


#: at most this many exemplar primitives are coded in each learning iteration (random subset)
LEARN_SIGNALS = 8192


def build_dictionary(exemplar: np.ndarray, params: GuerinParams, rng: np.random.Generator) -> Dictionary:
    """The multi-resolution dictionary of an exemplar (array in metres, NaN nodata).

    ``complete``: every primitive of the exemplar (grid of ``step``, mirrored borders)
    that holds no nodata and is not flat. ``constrained``: ``n_atoms`` of them, drawn at
    random then improved ``iterations`` times by the paper's problem 2 (code every
    primitive, then replace each atom by the primitive that best fits the restricted
    error of the primitives using it). ``ksvd``: K-SVD on the joined vectors (low, high /
    factor), the atoms' SVD update computed with ``scipy.linalg.svd``.

    Raises
    ------
    InputError : the exemplar has no usable primitive (too small, all nodata or flat).
    """
    R, f = params.radius, params.factor
    step = primitive_step(R, params.step)
    ex = np.asarray(exemplar, float)
    if ex.ndim != 2 or min(ex.shape) < 2 * R:
        raise InputError(f"the exemplar ({' x '.join(map(str, ex.shape))} cells) is smaller than one patch "
                         f"({2 * R} x {2 * R} cells at radius={R}); pass a larger exemplar DEM or a smaller radius")
    high, low, mean = primitives(ex, R, f, step)
    lo, hi, idx = _normalised_pairs(high, low, mean, params.max_detail)
    if idx.size == 0:
        raise InputError("the exemplar has no usable patch (every patch holds nodata, is flat, or has more "
                         f"detail than max_detail={params.max_detail} x its coarse relief); pass an exemplar DEM "
                         "with relief, or raise max_detail")
    if params.dictionary == "complete":
        return Dictionary(lo, hi, idx, R, f, step)
    n = min(params.n_atoms, idx.size)
    pick = np.sort(rng.choice(idx.size, size=n, replace=False))
    train = np.sort(rng.choice(idx.size, size=min(idx.size, LEARN_SIGNALS), replace=False))
    signals = low[idx[train]] - mean[idx[train], None]
    if params.dictionary == "constrained":
        atoms = pick.copy()
        for _ in range(params.iterations):
            x = sparse_codes(lo[atoms], signals, params.sparsity).toarray()
            approx = x @ lo[atoms]
            for j in range(atoms.size):
                users = np.flatnonzero(x[:, j])
                if users.size == 0:
                    continue
                err = signals[users] - approx[users] + np.outer(x[users, j], lo[atoms[j]])
                best = int(((err @ lo.T) ** 2).sum(axis=0).argmax())
                new = lo[best]
                approx[users] += np.outer(x[users, j], -lo[atoms[j]])
                # keep the users' codes on the new atom at their least-squares value
                x[users, j] = err @ new
                approx[users] += np.outer(x[users, j], new)
                atoms[j] = best
        atoms = np.unique(atoms)
        return Dictionary(lo[atoms], hi[atoms], idx[atoms], R, f, step)
    # ksvd on joined vectors: the low part is the coding space, the high part follows
    from scipy.linalg import svd

    hs = hi.reshape(hi.shape[0], -1) / f
    joined = np.concatenate([lo, hs], axis=1)
    d = joined[pick] / np.linalg.norm(joined[pick], axis=1)[:, None]
    it = idx[train]
    ysig = np.concatenate([signals, (high[it] - mean[it, None, None]).reshape(it.size, -1) / f], axis=1)
    for _ in range(params.iterations):
        x = sparse_codes(d, ysig, params.sparsity).toarray()
        for j in range(d.shape[0]):
            users = np.flatnonzero(x[:, j])
            if users.size == 0:
                continue
            err = ysig[users] - x[users] @ d + np.outer(x[users, j], d[j])
            u, sv, vt = svd(err.T, full_matrices=False)
            d[j] = u[:, 0]
            x[users, j] = sv[0] * vt[0]
    kl = lo.shape[1]
    lnorm = np.linalg.norm(d[:, :kl], axis=1)
    keep = lnorm > 1e-9
    d = d[keep]
    low_atoms = d[:, :kl] / lnorm[keep, None]
    high_atoms = (d[:, kl:] * f / lnorm[keep, None]).reshape(-1, 2 * R, 2 * R)
    return Dictionary(low_atoms, high_atoms, np.full(low_atoms.shape[0], -1), R, f, step)


def synthesize(coarse: np.ndarray, dictionary: Dictionary, sparsity: int, shape: tuple[int, int]) -> np.ndarray:
    """The Sparse Construction Tree of a coarse terrain, evaluated on the fine grid.

    ``coarse`` (my, mx) has cells of ``factor`` fine cells (coarse cell k covers fine cells
    ``[k f, (k + 1) f)``); ``shape`` (ny, nx) <= (my f, mx f) is the fine grid. Each
    primitive's low patch is the coarse cells under its ``2R x 2R`` square; its code over
    ``dictionary.low`` rebuilds it with ``dictionary.high``, and the primitives are blended
    with the ``(1 - r^2)^3`` weights. With ``factor`` 1 and the complete dictionary of
    ``coarse`` itself at s = 1 the result is ``coarse`` (exact reconstruction, §4.3).
    """
    R, f = dictionary.radius, dictionary.factor
    ny, nx = shape
    step = dictionary.step
    rows, cols = _centres(ny, step), _centres(nx, step)
    z = np.asarray(coarse, float)
    lw = 2 * R // f
    pad = 2 * R
    if step % f == 0 and R % f == 0:
        cp = _pad(z, pad // f + lw)
        off = (pad // f + lw)
        win = np.lib.stride_tricks.sliding_window_view(cp, (lw, lw))
        low = win[np.ix_((rows - R) // f + off, (cols - R) // f + off)].reshape(-1, lw * lw)
    else:  # centres between coarse cells: bicubic samples of the coarse terrain
        from scipy.ndimage import map_coordinates

        m = np.arange(lw)
        rr = ((rows[:, None] - R) / f + m[None, :] + 0.5) - 0.5
        cc = ((cols[:, None] - R) / f + m[None, :] + 0.5) - 0.5
        gr = np.broadcast_to(rr[:, None, :, None], (rows.size, cols.size, lw, lw))
        gc = np.broadcast_to(cc[None, :, None, :], (rows.size, cols.size, lw, lw))
        low = map_coordinates(z, [gr.ravel(), gc.ravel()], order=3, mode="mirror").reshape(-1, lw * lw)
    mean = low.mean(axis=1)
    x = sparse_codes(dictionary.low, low - mean[:, None], sparsity)
    w = weight_kernel(R)
    side = 2 * R
    hny, hnx = rows[-1] + R + pad, cols[-1] + R + pad
    num = np.zeros((hny, hnx))
    den = np.zeros((hny, hnx))
    ptr, ind, val = x.indptr, x.indices, x.data
    k = 0
    for r in rows:
        for c in cols:
            js, xs = ind[ptr[k]:ptr[k + 1]], val[ptr[k]:ptr[k + 1]]
            if js.size == 1:
                patch = mean[k] + xs[0] * dictionary.high[js[0]]
            else:
                patch = mean[k] + np.tensordot(xs, dictionary.high[js], axes=1)
            r0, c0 = r - R + pad, c - R + pad
            num[r0:r0 + side, c0:c0 + side] += w * patch
            den[r0:r0 + side, c0:c0 + side] += w
            k += 1
    with np.errstate(invalid="ignore", divide="ignore"):  # uncovered cells are in the cropped margin
        return (num / den)[pad:pad + ny, pad:pad + nx]


def amplify(coarse: np.ndarray, exemplar: np.ndarray, params: GuerinParams, rng: np.random.Generator,
            shape: tuple[int, int] | None = None, dictionary: Dictionary | None = None) -> np.ndarray:
    """Amplify ``coarse`` by ``params.factor`` with an exemplar at the fine cell (§5.3).

    ``exemplar`` must already be at the fine cell size. Returns the fine terrain of
    ``shape`` (default ``factor x coarse.shape``).
    """
    d = dictionary if dictionary is not None else build_dictionary(exemplar, params, rng)
    f = params.factor
    shape = shape or (coarse.shape[0] * f, coarse.shape[1] * f)
    return synthesize(coarse, d, params.sparsity, shape)


def coarse_from_tree(tree, rivers, grid: Grid) -> np.ndarray:
    """The coarse terrain of a tree on ``grid``: its ridges (linear from peak to saddle) and
    rivers rasterised (:func:`orokit.generators.belhadj.tree_skeleton`), the other cells
    interpolated from the 16 nearest of them (``scipy.interpolate.RBFInterpolator``,
    polyharmonic kernel r with a linear trend: planes are reproduced exactly)."""
    from scipy.interpolate import RBFInterpolator

    from orokit.generators.belhadj import tree_skeleton

    z, state = tree_skeleton(tree, rivers, grid)
    known = state == 1
    iy, ix = np.nonzero(known)
    if iy.size == 0:
        raise InputError("no peak, saddle or river of the Divide Tree lies inside the grid")
    out = np.where(known, z, np.nan).astype(float)
    qy, qx = np.nonzero(~known)
    if qy.size:
        pts = np.column_stack([iy, ix]).astype(float)
        vals = z[known].astype(float)
        if iy.size >= 3 and np.linalg.matrix_rank(pts - pts.mean(axis=0)) == 2:
            interp = RBFInterpolator(pts, vals, neighbors=min(16, iy.size), kernel="linear")
        else:  # one point or a line of them: the nearest known cell
            interp = RBFInterpolator(pts, vals, neighbors=1, kernel="linear", degree=0)
        out[qy, qx] = interp(np.column_stack([qy, qx]).astype(float))
    return out


def _exemplar_cell(exemplar: xr.DataArray) -> float:
    """The exemplar's cell size in metres (the larger of dx, dy)."""
    t = exemplar.rio.transform() if hasattr(exemplar, "rio") else None
    cell = exemplar.attrs.get("cell_size_m")  # a number, or (dx, dy) since the attrs rename
    if cell is None and t is not None and not (exemplar.rio.crs is not None and exemplar.rio.crs.is_geographic):
        cell = (abs(t.a), abs(t.e))
    res = float(np.max(np.abs(np.atleast_1d(np.asarray(cell, float))))) if cell is not None else 0.0
    if not (res > 0):
        raise InputError("the exemplar DEM has no cell size in metres; read it with a cell size (--cell-size)")
    return res


def _exemplar_at(exemplar: xr.DataArray, cell_m: float) -> tuple[np.ndarray, float]:
    """The exemplar's values and its cell size (m); block-averaged/resampled to ``cell_m``
    when its cells are finer."""
    res = _exemplar_cell(exemplar)
    z = np.asarray(exemplar.values, float)
    if res < cell_m * (1 - 1e-6):
        from scipy.ndimage import gaussian_filter, zoom

        q = cell_m / res
        filled = np.where(np.isfinite(z), z, np.nanmean(z))
        z2 = zoom(gaussian_filter(filled, 0.5 * q), 1.0 / q, order=1)
        nan = zoom(np.isfinite(z).astype(float), 1.0 / q, order=1) < 0.999
        z = np.where(nan, np.nan, z2)
        res = cell_m
    return z, res


def learn(exemplar: xr.DataArray, grid: Grid, params: GuerinParams, rng: np.random.Generator) -> Dictionary:
    """The dictionary :func:`render` learns from ``exemplar`` for ``grid`` (at the working cell
    ``max(grid cell, exemplar cell)``); pass it back as ``render(..., learned=...)`` to render
    several trees without learning again (same raster as learning inside)."""
    ex, _ = _exemplar_at(exemplar, grid.cell_size_m)
    return build_dictionary(ex, resolve_max_detail(params, coarse_dem=bool(params.coarse)), rng)


#: ``max_detail`` when the coarse terrain is the tree's interpolated ridges and rivers
TREE_MAX_DETAIL = 1.0


def resolve_max_detail(params: GuerinParams, *, coarse_dem: bool) -> GuerinParams:
    """``params`` with a NaN ``max_detail`` set from the coarse source: :data:`TREE_MAX_DETAIL`
    for the tree's coarse terrain, ``inf`` (every primitive, the paper) for a coarse DEM.

    >>> resolve_max_detail(GuerinParams(), coarse_dem=False).max_detail
    1.0
    >>> resolve_max_detail(GuerinParams(), coarse_dem=True).max_detail
    inf
    """
    if not np.isnan(params.max_detail):
        return params
    return replace(params, max_detail=float("inf") if coarse_dem else TREE_MAX_DETAIL)


def render(tree, rivers, grid: Grid, rng: np.random.Generator, params: GuerinParams | None = None, *,
           exemplar: xr.DataArray | None = None, coarse: xr.DataArray | None = None,
           learned: Dictionary | None = None) -> xr.DataArray:
    """Elevation raster of a Divide Tree by Guérin 2016 amplification (pure: no file IO).

    Notes
    -----
    1. Working cell ``h = max(grid cell, exemplar cell)``; the dictionary (H, L) comes from
       the exemplar's primitives at ``h`` (:func:`build_dictionary`).
    2. Coarse terrain at ``factor x h``: :func:`coarse_from_tree` (ridges + rivers,
       interpolated), or ``coarse`` (a real DEM resampled bicubically onto that grid).
    3. :func:`synthesize`: codes over L (OMP), rebuilds with H, blends the primitives.
    4. A finer output grid gets the working raster resampled bicubically.
    """
    from scipy.ndimage import map_coordinates

    from orokit.raster.rasterize import make_grid

    params = params or GuerinParams()
    crs = check_crs(tree)
    if params.coarse and coarse is None:
        raise InputError(f"coarse={params.coarse!r} is a file the caller reads: pass "
                         "render_terrain(..., inputs={'coarse': dem}) (the CLI does it)")
    if exemplar is None:
        raise InputError("generator guerin needs an exemplar DEM to build its dictionary (CLI: --exemplar DEM)")
    params = resolve_max_detail(params, coarse_dem=coarse is not None or bool(params.coarse))
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    if learned is None:
        learned = learn(exemplar, grid, params, rng)
        timings["dictionary"] = time.perf_counter() - t0
    elif (learned.radius, learned.factor, learned.step) != (params.radius, params.factor,
                                                            primitive_step(params.radius, params.step)):
        raise InputError(f"the learned dictionary has radius {learned.radius}, factor {learned.factor}, step "
                         f"{learned.step}; the parameters ask for radius {params.radius}, factor {params.factor}, "
                         f"step {params.step}: learn it again")
    d = learned
    h = max(_exemplar_cell(exemplar), grid.cell_size_m)
    t0 = time.perf_counter()
    x0, y0, x1, y1 = grid.extent
    f = params.factor
    same = abs(h - grid.cell_size_m) <= 1e-9 * h
    ny_h = grid.ny if same else max(int(np.ceil((y1 - y0) / h - 1e-9)), 1)
    nx_h = grid.nx if same else max(int(np.ceil((x1 - x0) / h - 1e-9)), 1)
    cgrid = make_grid((x0, y1 - f * h * int(np.ceil(ny_h / f)), x0 + f * h * int(np.ceil(nx_h / f)), y1), f * h)
    if coarse is None:
        zc = coarse_from_tree(tree, rivers, cgrid)
    else:
        zc = _resample(coarse, cgrid)
    timings["coarse"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    fine = synthesize(zc, d, params.sparsity, (ny_h, nx_h))
    timings["synthesis"] = time.perf_counter() - t0
    if not same:
        t0 = time.perf_counter()
        xc, yc = grid.centres()
        rr = (y1 - yc) / h - 0.5
        cc = (xc - x0) / h - 0.5
        fine = map_coordinates(fine, np.meshgrid(rr, cc, indexing="ij"), order=3, mode="nearest")
        timings["resample"] = time.perf_counter() - t0
    logger.info("guerin: %d atoms (%s), coarse %d x %d at %.0f m, working cell %.1f m", d.n_atoms,
                params.dictionary, zc.shape[1], zc.shape[0], f * h, h)
    counts = {"atoms": d.n_atoms, "coarse_cells": int(zc.size)}
    return as_dataarray(fine.astype(np.float32), grid, crs, {"timings": timings, "cell_counts": counts,
                                                             "derived": {"max_detail": params.max_detail if np.isfinite(params.max_detail) else "inf"}})


def _resample(dem: xr.DataArray, grid: Grid) -> np.ndarray:
    """A DEM's values at ``grid``'s cell centres (bicubic; nearest beyond its edge), by its
    transform. Raises when the DEM does not overlap the grid."""
    from scipy.ndimage import map_coordinates

    t = dem.rio.transform()
    z = np.asarray(dem.values, float)
    if not np.isfinite(z).any():
        raise InputError("the coarse DEM holds only nodata")
    z = np.where(np.isfinite(z), z, np.nanmean(z))
    xc, yc = grid.centres()
    inv = ~t
    cols = np.array([inv * (x, yc[0]) for x in xc])[:, 0] - 0.5
    rows = np.array([inv * (xc[0], y) for y in yc])[:, 1] - 0.5
    if rows.max() < -0.5 or rows.min() > z.shape[0] - 0.5 or cols.max() < -0.5 or cols.min() > z.shape[1] - 0.5:
        raise InputError("the coarse DEM does not overlap the output grid; pass --extent inside it")
    return map_coordinates(z, np.meshgrid(rows, cols, indexing="ij"), order=3, mode="nearest")
