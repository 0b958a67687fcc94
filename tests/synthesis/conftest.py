"""Fixtures of the synthesis tests: small hand-built peak tables and terrain types."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from orokit.synthesis.terrain_type import TerrainType


def make_peak_table(n: int = 400, seed: int = 0, side_m: float = 40_000.0) -> pd.DataFrame:
    """A plausible peak table: elevations 300..2500 m, exponential prominences >= 30 m."""
    rng = np.random.default_rng(seed)
    z = rng.uniform(300.0, 2500.0, n)
    prom = np.minimum(30.0 + rng.exponential(120.0, n), z)
    x, y = rng.uniform(0, side_m, n), rng.uniform(0, side_m, n)
    ang = rng.uniform(0, 2 * np.pi, n)
    d = rng.gamma(2.0, 400.0, n)
    frame = pd.DataFrame({"x": x, "y": y, "elevation": z, "prominence": prom,
                          "saddle_x": x + d * np.cos(ang), "saddle_y": y + d * np.sin(ang)})
    top = int(np.argmax(z))
    frame.loc[top, ["saddle_x", "saddle_y"]] = np.nan
    frame.loc[top, "prominence"] = z[top]
    return frame


@pytest.fixture(scope="session")
def peak_factory():
    """The :func:`make_peak_table` builder."""
    return make_peak_table


@pytest.fixture(scope="session")
def peak_table() -> pd.DataFrame:
    return make_peak_table()


@pytest.fixture(scope="session")
def small_type(peak_table) -> TerrainType:
    return TerrainType.from_peaks(peak_table, area_km2=1600.0, name="test")


@pytest.fixture(scope="module")
def synthesized_type(small_type):
    """A 30 km tree synthesized from ``small_type`` and the type measured on it (a type that has a tree to record
    ridge slopes, neighbour gradients and its saddle level from)."""
    from orokit.synthesis import synthesize_divide_tree

    tree = synthesize_divide_tree(small_type, size_m=30_000.0, rng=2)
    return tree, TerrainType.from_divide_tree(tree, area_km2=900.0, min_prominence_m=30.0)
