"""Cross-sections of the ground across a Divide Tree's straight ridge pieces (issue 11: spokes and walls).

A render burns every tree piece (peak -> saddle) into the raster as a straight crest; where the real ground
beside that line is a plateau or a broad cone the render can still stand the line up as a thin spoke or a
knife-edged wall. The statistic: at points every ``step_m`` along each piece (``skip_peak_m`` from its peak,
``skip_saddle_m`` from its saddle), the ground's drop ``z(line) - (z(+o) + z(-o)) / 2`` at perpendicular offsets
``o``, sampled bilinearly on the grid; its median per offset, and the crest width, the smallest offset where the
drop reaches ``drop_m``. The same pieces on the real DEM and on the render of its tree compare like with like.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

__all__ = ["CrestSections", "crest_sections", "crest_width"]

#: perpendicular offsets (metres) of the default cross-section
OFFSETS_M = (100.0, 200.0, 400.0, 700.0, 1000.0, 1500.0, 2000.0)


@dataclass(frozen=True)
class CrestSections:
    """Drops ``(n, len(offsets_m))`` (metres, positive = the ground beside lies lower) at ``n`` points along the
    pieces; ``piece`` (n,) the piece of each point, ``along_m`` (n,) its distance from the piece's peak."""

    offsets_m: NDArray[np.float64]
    drop: NDArray[np.float64]
    piece: NDArray[np.int64]
    along_m: NDArray[np.float64]

    def median(self, mask: NDArray[np.bool_] | None = None) -> NDArray[np.float64]:
        """Median drop per offset over the points (those of ``mask``, one bool per piece); NaN without points."""
        d = self.drop if mask is None else self.drop[np.asarray(mask, bool)[self.piece]]
        if d.shape[0] == 0:
            return np.full(self.offsets_m.size, np.nan)
        return np.asarray(np.median(d, axis=0), float)


def crest_sections(z: NDArray[np.floating], transform: tuple[float, float, float], peak_xy: NDArray[np.floating],
                   saddle_xy: NDArray[np.floating], *, offsets_m: tuple[float, ...] = OFFSETS_M,
                   step_m: float = 200.0, skip_peak_m: float = 1000.0, skip_saddle_m: float = 400.0,
                   border_m: float | None = None, search_m: float = 0.0) -> CrestSections:
    """Cross-sections of the grid ``z`` across the straight pieces ``peak_xy[i] -> saddle_xy[i]`` ((m, 2) each).

    ``transform``: ``(x_west, y_north, cell_size_m)`` of ``z``'s north-up grid (cell centres half a cell in).
    Points lie every ``step_m`` from ``skip_peak_m`` past the peak to ``skip_saddle_m`` before the saddle; those
    whose widest section would leave the grid (within ``border_m``, default the largest offset plus one cell, of
    its edge) are dropped. With ``search_m`` > 0 each section is centred on the highest ground within ``search_m``
    of the line along its normal (sampled every ``search_m / 10``): a real crest meanders about the straight line
    from peak to saddle, and the drops are then measured from the crest itself.

    >>> y = (np.arange(101) - 50.0) * 20.0  # a cell centre on y = 0
    >>> z = np.tile(1000.0 - 0.1 * np.abs(y)[:, None], (1, 200))  # a tent ridge along y = 0, 0.1 m/m flanks
    >>> cs = crest_sections(z, (0.0, 1010.0, 20.0), np.array([[100.0, 0.0]]), np.array([[3900.0, 0.0]]),
    ...                     offsets_m=(100.0, 400.0))
    >>> cs.median().round(3).tolist(), int(cs.drop.shape[0])
    ([10.0, 40.0], 13)
    """
    z = np.asarray(z, float)
    x0, y0, res = (float(v) for v in transform)
    if not res > 0:
        raise ValueError(f"cell size must be > 0, got {res!r}")
    off = np.asarray(offsets_m, float)
    if off.size == 0 or not (off > 0).all():
        raise ValueError(f"offsets_m must be > 0 metres, got {offsets_m!r}")
    border = float(off.max() + search_m + res) if border_m is None else float(border_m)
    p, s = np.asarray(peak_xy, float).reshape(-1, 2), np.asarray(saddle_xy, float).reshape(-1, 2)
    length = np.hypot(*(s - p).T)
    pieces, along = [], []
    for i in np.flatnonzero(length > skip_peak_m + skip_saddle_m):
        d = np.arange(float(skip_peak_m), length[i] - skip_saddle_m + 1e-9, float(step_m))
        pieces.append(np.full(d.size, i, np.int64))
        along.append(d)
    piece = np.concatenate(pieces) if pieces else np.zeros(0, np.int64)
    dist = np.concatenate(along) if along else np.zeros(0)
    u = (s[piece] - p[piece]) / np.maximum(length[piece], 1e-9)[:, None]
    xy = p[piece] + dist[:, None] * u
    nrm = np.column_stack([-u[:, 1], u[:, 0]])
    ny, nx = z.shape
    xmax, ymin = x0 + nx * res, y0 - ny * res
    ok = ((xy[:, 0] >= x0 + border) & (xy[:, 0] <= xmax - border) & (xy[:, 1] >= ymin + border)
          & (xy[:, 1] <= y0 - border))
    piece, dist, xy, nrm = piece[ok], dist[ok], xy[ok], nrm[ok]

    def sample(q: NDArray[np.float64]) -> NDArray[np.float64]:
        rows, cols = (y0 - q[:, 1]) / res - 0.5, (q[:, 0] - x0) / res - 0.5
        return np.asarray(ndimage.map_coordinates(z, [rows, cols], order=1, mode="nearest"), float)

    if search_m > 0 and xy.shape[0]:
        shifts = np.linspace(-float(search_m), float(search_m), 21)
        zs = np.column_stack([sample(xy + t * nrm) for t in shifts])
        xy = xy + shifts[np.argmax(zs, axis=1)][:, None] * nrm
    z0 = sample(xy)
    drop = np.empty((xy.shape[0], off.size))
    for j, o in enumerate(off):
        drop[:, j] = z0 - 0.5 * (sample(xy + o * nrm) + sample(xy - o * nrm))
    return CrestSections(off, drop, piece, dist)


def crest_width(sections: CrestSections, drop_m: float) -> NDArray[np.float64]:
    """Per point, the smallest offset at which the ground lies ``drop_m`` below the line (inf: none within the
    widest offset): a spoke or a knife-edged wall is narrow, a plateau or a broad cone wide.

    >>> cs = CrestSections(np.array([100.0, 400.0]), np.array([[10.0, 40.0], [1.0, 2.0]]), np.zeros(2, np.int64),
    ...                    np.zeros(2))
    >>> crest_width(cs, 25.0).tolist()
    [400.0, inf]
    """
    reach = sections.drop >= float(drop_m)
    first = np.argmax(reach, axis=1)
    return np.where(reach.any(axis=1), sections.offsets_m[first], np.inf)
