"""Synthetic peak tables for classification tests (contract columns, metres, local metric grid)."""
from __future__ import annotations

import numpy as np
import pandas as pd


def make_peaks(n: int = 600, *, extent_m: float = 60_000.0, prom_scale: float = 150.0, base_m: float = 500.0,
               relief_m: float = 1500.0, saddle_scale_m: float = 1500.0, rng: int = 0) -> pd.DataFrame:
    """Random peaks with the orokit peaks-table columns; isolation = nearest higher peak (brute force)."""
    g = np.random.default_rng(rng)
    x = g.uniform(0, extent_m, n)
    y = g.uniform(-extent_m, 0, n)
    h = base_m + relief_m * g.beta(2, 3, n)
    prom = np.minimum(30 + g.exponential(prom_scale, n), h)
    ang = g.uniform(0, 2 * np.pi, n)
    d = g.exponential(saddle_scale_m, n)
    top = int(np.argmax(h))
    prom[top] = h[top]
    sx, sy = x + d * np.cos(ang), y + d * np.sin(ang)
    sx[top] = sy[top] = np.nan
    dist = np.hypot(x[:, None] - x[None], y[:, None] - y[None])
    dist[h[None, :] <= h[:, None]] = np.inf
    j = np.argmin(dist, axis=1)
    iso = dist[np.arange(n), j]
    ix, iy = x[j].copy(), y[j].copy()
    iso[top] = ix[top] = iy[top] = np.nan
    return pd.DataFrame({
        "x": x, "y": y, "elevation": h, "prominence": prom, "saddle_x": sx, "saddle_y": sy,
        "isolation": iso, "isolation_x": ix, "isolation_y": iy, "prominence_exact": True,
    }, index=pd.RangeIndex(n, name="peak_id"))

