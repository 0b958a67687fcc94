from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from orokit.errors import InputError
from orokit.metrics.disk import clamped_distance, disk_metrics, dominance, dominance_group, relative_elevation


def test_dominance_and_groups():
    d = dominance(np.array([1000.0, 500.0, 0.0, 100.0]), np.array([1000.0, 100.0, 10.0, 150.0]))
    assert d[0] == 1.0 and d[1] == pytest.approx(0.2) and np.isnan(d[2]) and d[3] == 1.0
    assert dominance_group(np.array([0.0, 0.004, 0.5, 1.0, np.nan])).tolist() == [0, 1, 10, 11, -1]


def test_relative_elevation_conventions():
    h = np.array([200.0, 600.0, 1000.0])
    assert relative_elevation(h, convention="minmax").tolist() == [0.0, 0.5, 1.0]
    assert relative_elevation(h, convention="max").tolist() == pytest.approx([0.2, 0.6, 1.0])
    assert relative_elevation(np.array([5.0, 5.0])).tolist() == [1.0, 1.0]
    with pytest.raises(InputError):
        relative_elevation(h, convention="median")  # type: ignore[arg-type]


def test_clamping_and_relevance():
    assert clamped_distance(np.array([500.0, 20_000.0, np.nan]), 10_000.0).tolist() == [0.05, 1.0, 1.0]
    p = pd.DataFrame({"elevation": [1000.0, 500.0], "prominence": [400.0, 100.0],
                      "saddle_distance_m": [1.0, 1.0], "saddle_direction_deg": [0.0, 370.0],
                      "isolation_m": [np.nan, 1.0], "isolation_direction_deg": [np.nan, -90.0]})
    m = disk_metrics(p, radius_m=1000.0, relative_elevation_convention="max")
    assert m["relative_prominence"].tolist() == [1.0, 0.25]
    assert m["relevance"].tolist() == pytest.approx([1.0, np.sqrt(0.25 * 0.5)])
    assert m["saddle_direction"].tolist() == [0.0, 10.0]
    assert m["isolation_direction"].iloc[1] == 270.0 and m["isolation_distance"].iloc[0] == 1.0
    with pytest.raises(InputError):
        disk_metrics(p.drop(columns="isolation_m"), radius_m=1000.0)
    with pytest.raises(InputError):
        disk_metrics(p, radius_m=0.0)
