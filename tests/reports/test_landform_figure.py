"""Landform figure: shared colour scale, km axes, labelled histogram axes."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402


def test_plot_landforms_shares_one_colour_scale_and_labels_axes(make_dem):
    import matplotlib.pyplot as plt

    from orokit.reports.landform import plot_landforms

    rng = np.random.default_rng(0)
    a = make_dem(rng.random((60, 80)) * 300 + 1000, res=100.0)
    b = make_dem(rng.random((60, 80)) * 900 + 200, res=100.0)
    fig = plot_landforms({"real": a, "twin": b}, title="demo")
    images = [im for ax in fig.axes for im in ax.get_images() if im.get_cmap().name == "terrain"]
    assert len(images) == 2
    assert {im.get_clim() for im in images} == {(float(b.values.min()), float(a.values.max()))}
    # km from the south-west corner: 80 cells x 100 m = 8 km wide, 6 km high
    assert images[0].get_extent() == [0.0, 8.0, 0.0, 6.0]
    labels = " ".join(ax.get_xlabel() + " " + ax.get_ylabel() for ax in fig.axes)
    for needle in ("slope (degrees", "relief in ~1 km windows (m)", "share of cells", "km north", "elevation (m)"):
        assert needle in labels
    assert fig.dpi >= 150
    plt.close(fig)
