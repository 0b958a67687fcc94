"""The automatic C_H's low ground as a network (``SynthesisParams.valley_network``, issue 11, session 16).

A ranked Gaussian field's low excursion set is isolated basins; folding a second field
(``|h|``) puts the low values on its zero lines, a network that crosses the domain.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from orokit.errors import InputError
from orokit.synthesis.controls import make_domain, random_elevation_fields
from orokit.synthesis.terrain_type import FeatureHistogram
from orokit.synthesis.tree import SynthesisParams, synthesize_divide_tree


def _low_ground(field: np.ndarray, q: float = 25.0) -> tuple[float, int]:
    """Share of the lowest q % of the cells in their largest 8-connected piece, and how many sides it touches."""
    low = field <= np.percentile(field, q)
    lab, _ = ndimage.label(low, structure=np.ones((3, 3)))
    sizes = np.bincount(lab.ravel())[1:]
    big = lab == 1 + sizes.argmax()
    return float(sizes.max() / low.sum()), sum(int(e.any()) for e in (big[0], big[-1], big[:, 0], big[:, -1]))


def test_folded_noise_joins_the_low_ground_into_a_network():
    domain = make_domain(60_000.0, grid_cells=128)
    hist = FeatureHistogram.from_values(np.linspace(500, 3500, 400), np.linspace(500, 3500, 13))
    plain, folded = [], []
    for seed in range(8):
        a = next(random_elevation_fields(domain, hist, correlation_m=4000.0, rng=seed))
        b = next(random_elevation_fields(domain, hist, correlation_m=4000.0, rng=seed, valley_weight=1.0))
        # both follow the histogram
        assert np.quantile(b, [0.1, 0.5, 0.9]) == pytest.approx(np.quantile(a, [0.1, 0.5, 0.9]), rel=0.02)
        plain.append(_low_ground(a))
        folded.append(_low_ground(b))
    (p_share, p_sides), (f_share, f_sides) = np.mean(plain, axis=0), np.mean(folded, axis=0)
    print("largest low piece: share / sides touched, plain", p_share, p_sides, "folded", f_share, f_sides)
    # the largest piece of low ground holds more of it and reaches across the domain
    assert f_share > 1.3 * p_share
    assert f_sides > p_sides + 1.5


def test_weight_zero_draws_nothing_more_and_the_tree_is_unchanged(small_type):
    domain = make_domain(40_000.0, grid_cells=64)
    hist = FeatureHistogram.from_values(np.linspace(500, 3500, 400), np.linspace(500, 3500, 13))
    g0, g1 = np.random.default_rng(5), np.random.default_rng(5)
    a = next(random_elevation_fields(domain, hist, correlation_m=4000.0, rng=g0))
    b = next(random_elevation_fields(domain, hist, correlation_m=4000.0, rng=g1, valley_weight=0.0))
    assert np.array_equal(a, b) and g0.integers(2**62) == g1.integers(2**62)
    t0 = synthesize_divide_tree(small_type, size_m=25_000, rng=2, params=SynthesisParams(valley_network=0.0))
    t2 = synthesize_divide_tree(small_type, size_m=25_000, rng=2, params=SynthesisParams(valley_network=0.7))
    t2.validate()
    assert not t0.peaks[["x", "y"]].equals(t2.peaks[["x", "y"]])


@pytest.mark.parametrize("bad", [-0.1, 1.5, True, "a", float("nan")])
def test_bad_valley_network_is_refused(bad):
    with pytest.raises(InputError, match="valley_network"):
        SynthesisParams(valley_network=bad)  # type: ignore[arg-type]
