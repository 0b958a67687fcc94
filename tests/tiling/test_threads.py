"""The chunked engine gives identical tables with 1, 2 and 4 dask threads."""
from __future__ import annotations

import dask
import numpy as np
import pytest

import orokit
from orokit.io.dem import read_dem


def _tables(result):
    peaks = result.peaks.drop(columns="geometry")
    saddles = result.saddles.drop(columns="geometry")
    return peaks, saddles


@pytest.mark.realdata
def test_chunks_with_1_2_4_threads_identical(real_data):
    dem = read_dem(real_data("dems/karakoram.png"), z_units="ft", cell_size_m=92.61)
    runs = {}
    for n in (1, 2, 4):
        with dask.config.set(scheduler="threads", num_workers=n):
            runs[n] = _tables(orokit.analyze(dem, min_prominence_m=30.0, chunks=100))
    ref_peaks, ref_saddles = runs[1]
    assert len(ref_peaks) > 100 and ref_peaks["isolation"].notna().sum() > 100
    for n in (2, 4):
        peaks, saddles = runs[n]
        assert list(peaks.columns) == list(ref_peaks.columns)
        for c in ref_peaks.columns:
            np.testing.assert_array_equal(peaks[c].to_numpy(), ref_peaks[c].to_numpy(), err_msg=f"{n} threads: {c}")
        for c in ref_saddles.columns:
            np.testing.assert_array_equal(saddles[c].to_numpy(), ref_saddles[c].to_numpy(),
                                          err_msg=f"{n} threads: saddles {c}")
