from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from orokit.errors import SchemaError
from orokit.metrics.disk import disk_metrics
from orokit.sampling.histograms import FeatureBins, HistogramSpec, disk_histograms


def test_paper_spec_layout():
    spec = HistogramSpec.paper()
    # Table 1: 8 features x 20 bins... 7 x 20 + 2 x 12 + 12 dominance groups
    assert [f.n_bins for f in spec.features] == [20, 12, 20, 12, 20, 12, 20, 20, 20, 20]
    assert len(spec.columns) == 176 and len(set(spec.columns)) == 176
    assert spec.columns[20] == "dominance_groups_0"
    assert HistogramSpec.from_dict(spec.to_dict()) == spec


def test_bins_hand_counts():
    fb = FeatureBins("f", (0.0, 0.5, 1.0))
    assert fb.counts(np.array([0.0, 0.25, 0.5, 1.0, np.nan])).tolist() == [2, 2]
    prom = HistogramSpec.paper().select(["prominence"]).features[0]
    c = prom.counts(np.array([50.0, 150.0, 2500.0, 1999.0]))
    assert c[0] == 1 and c[1] == 1 and c[19] == 2 and c.sum() == 4


def test_bad_edges():
    with pytest.raises(SchemaError):
        FeatureBins("f", (0.0, 0.0, 1.0))


def _peaks():
    # hand-made disk with 4 peaks, R = 10 km
    return pd.DataFrame({
        "elevation": [1000.0, 800.0, 600.0, 400.0],
        "prominence": [1000.0, 168.0, 36.0, 40.0],
        "saddle_distance_m": [np.nan, 2500.0, 12000.0, 700.0],
        "saddle_direction_deg": [np.nan, 10.0, 95.0, 359.0],
        "isolation_m": [np.nan, 5000.0, 1200.0, 30000.0],
        "isolation_direction_deg": [np.nan, 185.0, 200.0, 91.0],
    })


def test_disk_histograms_hand_values():
    m = disk_metrics(_peaks(), radius_m=10_000.0)
    h = disk_histograms(m, HistogramSpec.paper(), normalize=False)
    # dominance 1.0, 0.21, 0.06, 0.1 -> bins 19, 4, 1, 2
    assert h[[f"dominance_{i}" for i in range(20)]].to_numpy().nonzero()[0].tolist() == [1, 2, 4, 19]
    # dominance groups: 0.06 -> [0.042, 0.07) = 5; 0.1 -> [0.07, 0.105) = 6; 0.21 -> [0.14, 0.245) = 8; 1 -> 11
    assert h[[f"dominance_groups_{i}" for i in range(12)]].to_numpy().nonzero()[0].tolist() == [5, 6, 8, 11]
    # minmax relative elevation: 1, 2/3, 1/3, 0 -> bins 19, 13, 6, 0
    assert h[[f"relative_elevation_{i}" for i in range(20)]].to_numpy().nonzero()[0].tolist() == [0, 6, 13, 19]
    # saddle distance clamped at R: nan->1, 0.25, 1.2->1, 0.07 -> bins 19, 5, 19, 1
    sd = h[[f"saddle_distance_{i}" for i in range(20)]].to_numpy()
    assert sd[19] == 2 and sd[5] == 1 and sd[1] == 1
    # directions: the top peak has none; 10 -> 0, 95 -> 3, 359 -> 11 (30-degree bins)
    d = h[[f"saddle_direction_{i}" for i in range(12)]].to_numpy()
    assert d.sum() == 3 and d[0] == d[3] == d[11] == 1
    # prominence bins of 100 m: 1000 -> 10, 168 -> 1, 36 and 40 -> 0
    p = h[[f"prominence_{i}" for i in range(20)]].to_numpy()
    assert p[10] == 1 and p[1] == 1 and p[0] == 2
    hn = disk_histograms(m)
    for f in HistogramSpec.paper().features:
        assert hn[f.columns].sum() == pytest.approx(1.0)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.floats(1, 9000), st.floats(0, 1), st.floats(0, 50_000), st.floats(0, 359.9)),
                min_size=1, max_size=40),
       st.floats(1000, 50_000))
def test_counts_sum_to_peaks(rows, radius):
    h = np.array([r[0] for r in rows])
    df = pd.DataFrame({"elevation": h, "prominence": h * np.array([r[1] for r in rows]),
                       "saddle_distance_m": [r[2] for r in rows], "saddle_direction_deg": [r[3] for r in rows],
                       "isolation_m": [r[2] for r in rows], "isolation_direction_deg": [r[3] for r in rows]})
    m = disk_metrics(df, radius_m=radius)
    counts = disk_histograms(m, normalize=False)
    spec = HistogramSpec.paper()
    # relative prominence (and relevance, its product with relative elevation) is undefined when no
    # peak has a prominence > 0: those peaks are left out of both histograms
    defined = len(rows) if m["prominence"].max() > 0 else 0
    for f in spec.features:
        expected = defined if f.name in ("relative_prominence", "relevance") else len(rows)
        assert counts[f.columns].sum() == expected, f.name
    assert counts[spec.groups()["dominance"]].sum() == len(rows)
    assert counts[spec.groups()["saddle_distance"]].sum() == len(rows)
