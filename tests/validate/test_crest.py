"""Cross-sections across straight ridge pieces (orokit.validate.crest) on analytic surfaces."""
from __future__ import annotations

import numpy as np
import pytest

from orokit.validate.crest import crest_sections, crest_width

RES = 20.0
N = 401  # 8 km square, a cell centre on the middle


def _grid():
    """Cell-centre coordinates of an N x N north-up grid centred on (0, 0); its transform."""
    c = (np.arange(N) - N // 2) * RES
    x, y = np.meshgrid(c, -c)  # row 0 is the north edge
    return x, y, (float(c[0] - RES / 2), float(-c[0] + RES / 2), RES)


def test_gaussian_ridge_on_a_diagonal():
    # a ridge of height H and width w along the line y = x: drop(o) = H (1 - exp(-o^2 / 2 w^2)) at every point
    x, y, tr = _grid()
    h, w = 300.0, 500.0
    across = (y - x) / np.sqrt(2.0)
    z = h * np.exp(-across ** 2 / (2 * w * w))
    cs = crest_sections(z, tr, np.array([[-2500.0, -2500.0]]), np.array([[2500.0, 2500.0]]),
                        offsets_m=(100.0, 400.0, 1000.0), step_m=200.0, skip_peak_m=500.0, skip_saddle_m=500.0)
    assert cs.drop.shape[0] > 5
    expect = h * (1.0 - np.exp(-np.array([100.0, 400.0, 1000.0]) ** 2 / (2 * w * w)))
    assert np.allclose(cs.median(), expect, rtol=0.03, atol=1.5)
    # width at a third of the height: w sqrt(-2 ln(2/3)) = 450 m, so the 1000-m offset is the first to reach it
    assert np.all(crest_width(cs, h / 3.0) == 1000.0)
    assert np.all(np.isinf(crest_width(cs, 1.01 * h)))


def test_cone_is_round_and_a_tent_is_a_spoke():
    # along a radius of a cone z = H - s r the ground beside falls by s (sqrt(d^2 + o^2) - d): at 2 km from the
    # apex, 2.5 m at 100 m and 98 m at 700 m; a tent ridge of the same flank slope falls s o
    x, y, tr = _grid()
    s = 0.3
    cone = 2000.0 - s * np.hypot(x, y)
    tent = 2000.0 - s * np.abs(y)
    peak, saddle = np.array([[0.0, 0.0]]), np.array([[3800.0, 0.0]])
    kw = dict(offsets_m=(100.0, 700.0), step_m=100.0, skip_peak_m=2000.0, skip_saddle_m=1700.0, border_m=0.0)
    cc, ct = crest_sections(cone, tr, peak, saddle, **kw), crest_sections(tent, tr, peak, saddle, **kw)
    d = cc.along_m[:, None]
    o = np.array([100.0, 700.0])[None, :]
    assert np.allclose(cc.drop, s * (np.hypot(d, o) - d), atol=0.5)
    assert np.allclose(ct.drop, s * o, atol=1e-6)
    assert np.all(crest_width(cc, 25.0) == 700.0) and np.all(crest_width(ct, 25.0) == 100.0)


def test_points_near_the_border_and_short_pieces_are_dropped():
    x, y, tr = _grid()
    z = -np.abs(y)
    # a piece running to the grid's east edge: points within the widest offset + a cell (2020 m) of any edge go
    edge = N // 2 * RES + RES / 2  # 4010 m
    cs = crest_sections(z, tr, np.array([[-1000.0, 0.0]]), np.array([[4000.0, 0.0]]), offsets_m=(2000.0,),
                        skip_peak_m=0.0, skip_saddle_m=0.0)
    x_pt = -1000.0 + cs.along_m
    assert cs.drop.shape[0] == 15 and x_pt.max() <= edge - 2020.0 and x_pt.max() + 200.0 > edge - 2020.0
    assert np.allclose(cs.drop, 2000.0)
    wide = crest_sections(z, tr, np.array([[-1000.0, 3000.0]]), np.array([[1000.0, 3000.0]]), offsets_m=(2000.0,),
                          skip_peak_m=0.0, skip_saddle_m=0.0)
    assert wide.drop.shape[0] == 0  # 3 km north of the middle: the section would leave the grid
    short = crest_sections(z, tr, np.array([[0.0, 0.0]]), np.array([[1000.0, 0.0]]))
    assert short.drop.shape == (0, 7)
    with pytest.raises(ValueError, match="offsets_m"):
        crest_sections(z, tr, np.zeros((1, 2)), np.ones((1, 2)), offsets_m=(0.0,))


def test_search_centres_the_section_on_a_crest_beside_the_line():
    # the tent's crest runs 120 m north of the straight line (on a cell centre): without the search the section is
    # lopsided (drops 0.3 (|o - 120| + |o + 120|) / 2 - 0.3 x 120 below the off-crest point); with a 300-m search
    # (every 30 m) it is the tent's
    x, y, tr = _grid()
    s = 0.3
    z = 2000.0 - s * np.abs(y - 120.0)
    peak, saddle = np.array([[-3000.0, 0.0]]), np.array([[3000.0, 0.0]])
    kw = dict(offsets_m=(100.0, 400.0), step_m=200.0, skip_peak_m=0.0, skip_saddle_m=0.0)
    off = crest_sections(z, tr, peak, saddle, **kw)
    on = crest_sections(z, tr, peak, saddle, search_m=300.0, **kw)
    assert on.drop.shape[0] > 5
    np.testing.assert_allclose(off.median(), [0.0, 84.0], atol=1e-6)
    np.testing.assert_allclose(on.median(), [30.0, 120.0], atol=1e-6)
