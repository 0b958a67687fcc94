"""Columns set aside on disk and read back by rows (orokit.io.spill_io.SpilledColumns)."""
from __future__ import annotations

import gc

import numpy as np
import pytest

from orokit.io.spill_io import SpilledColumns


def test_columns_read_back_by_rows_with_their_types(tmp_path):
    store = SpilledColumns(parent=tmp_path / "made")
    values = {"f": np.linspace(0, 1, 1000), "i": np.arange(-5, 995, dtype=np.int64),
              "b": np.arange(1000) % 3 == 0, "h": np.arange(1000, dtype=np.float32)}
    for name, v in values.items():
        store.put(name, v)
    assert len(store) == 4 and "f" in store and "x" not in store
    for name, v in values.items():
        for start, stop in ((0, 1000), (0, 1), (17, 514), (999, 1200), (-3, 2), (600, 600)):
            got = store.rows(name, start, stop)
            want = v[max(start, 0):stop]
            assert got.dtype == v.dtype and np.array_equal(got, want), (name, start, stop)
        assert np.array_equal(store.column(name), v)
    store.put("f", np.zeros(3))  # replaced
    assert store.size("f") == 3 and store.column("f").tolist() == [0, 0, 0]
    with pytest.raises(ValueError, match="1-D"):
        store.put("m", np.zeros((2, 2)))
    folder = store.folder
    assert folder.parent == tmp_path / "made"
    store.close()
    assert not folder.exists() and len(store) == 0


def test_the_folder_goes_with_the_store(tmp_path):
    store = SpilledColumns(parent=tmp_path)
    store.put("a", np.arange(10))
    folder = store.folder
    assert folder.exists()
    del store
    gc.collect()
    assert not folder.exists()
