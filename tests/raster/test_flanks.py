"""Flank cones of the skeleton (issue 11, steep terrain): valleys cut at the critical hillslope
slope, as deep as the tree's own relief allows."""
from __future__ import annotations

import numpy as np

from orokit.raster.params import RenderParams
from orokit.raster.skeleton import build_skeleton

from helpers.trees import small_tree


def _skeleton(tree, **kw):
    return build_skeleton(tree, extent=(0.0, 0.0, 8000.0, 8000.0), params=RenderParams(lam=200.0, **kw), rng=3)


def test_default_cones_cut_deeper_valleys_than_gentle_cones():
    """The default cones (``flank_slope`` 0.5, near the critical angle) put every river bed at or
    below where the session-8 cones (0.05) put it (same network; the bed is monotone in the cap),
    and far lower where the ridges are high; the samples follow."""
    tree = small_tree()
    assert RenderParams().flank_slope == 0.5 and RenderParams().flank_depth == 1.0
    gentle = _skeleton(tree, flank_slope=0.05)
    steep = _skeleton(tree)
    g, s = gentle.river_network.elevation, steep.river_network.elevation
    assert np.array_equal(gentle.river_network.receiver, steep.river_network.receiver)
    assert (s <= g + 1e-9).all()
    assert (s < g - 100.0).any()
    # the ground between ridges and rivers is lower on average (deeper valleys, not only beds)
    assert steep.tin.z.mean() < gentle.tin.z.mean() - 10.0

