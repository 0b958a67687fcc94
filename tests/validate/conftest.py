"""Fixtures of the round-trip tests: a small terrain type file to synthesize from, a small region model."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from orokit.synthesis.terrain_type import TerrainType


@pytest.fixture(scope="session")
def small_type_file(tmp_path_factory):
    """Terrain type of 300 random peaks on 40 x 40 km (about 0.19 peaks >= 30 m per km2)."""
    rng = np.random.default_rng(0)
    n = 300
    z = rng.uniform(400.0, 1800.0, n)
    prom = np.minimum(30.0 + rng.exponential(100.0, n), z)
    x, y = rng.uniform(0, 40_000.0, n), rng.uniform(0, 40_000.0, n)
    ang, d = rng.uniform(0, 2 * np.pi, n), rng.gamma(2.0, 400.0, n)
    peaks = pd.DataFrame({"x": x, "y": y, "elevation": z, "prominence": prom,
                          "saddle_x": x + d * np.cos(ang), "saddle_y": y + d * np.sin(ang)})
    top = int(np.argmax(z))
    peaks.loc[top, ["saddle_x", "saddle_y"]] = np.nan
    peaks.loc[top, "prominence"] = z[top]
    ttype = TerrainType.from_peaks(peaks, area_km2=1600.0, name="test")
    return ttype.save(tmp_path_factory.mktemp("type") / "test.json")


@pytest.fixture(scope="session")
def region_model(tmp_path_factory):
    """A terrain-feature model of R = 10 km trained on two made-up regions (``helpers.region_model``)."""
    from helpers.region_model import train_region_model

    return train_region_model(tmp_path_factory.mktemp("model") / "regions-10km.skops")
