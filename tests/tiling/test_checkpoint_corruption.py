"""Corrupt checkpoint chunks are recomputed with a warning, never a traceback (issue 15)."""
from __future__ import annotations

import pickle

import numpy as np
import pytest
from click.testing import CliRunner

import orokit
from orokit.errors import OrokitWarning, TilingError
from orokit.io.checkpoint_io import read_chunk


def _tables_equal(a, b):
    cols = ["row", "col", "elevation", "prominence"]
    assert a.peaks[cols].reset_index(drop=True).equals(b.peaks[cols].reset_index(drop=True))


@pytest.mark.parametrize("damage", ["truncate", "zero", "garbage", "pickle", "wrong_arrays"])
def test_corrupt_chunk_is_recomputed(make_dem, tmp_path, monkeypatch, damage):
    import orokit.tiling.engine as te

    z = np.random.default_rng(5).normal(size=(50, 60)).cumsum(0).cumsum(1)
    dem = make_dem(z)
    ck = tmp_path / "ck"
    a = orokit.analyze(dem, min_prominence_m=1.0, chunks=20, checkpoint=ck, scheduler="synchronous")
    target = sorted(ck.glob("chunk_*.npz"))[1]
    raw = target.read_bytes()
    if damage == "truncate":
        target.write_bytes(raw[: len(raw) // 2])
    elif damage == "zero":
        target.write_bytes(b"")
    elif damage == "garbage":
        target.write_bytes(np.random.default_rng(0).bytes(500))
    elif damage == "pickle":
        target.write_bytes(pickle.dumps({"meta": np.arange(7)}))
    else:
        np.savez(target, other=np.arange(3))
    with pytest.raises((TilingError, KeyError)):
        from orokit.tiling.engine import _load_summary

        _load_summary(str(target))
    calls = []
    real = te.chunk_summary
    monkeypatch.setattr(te, "chunk_summary", lambda *args, **kw: calls.append(args[1:3]) or real(*args, **kw))
    with pytest.warns(OrokitWarning, match=f"{target.name}.*recomputing that chunk"):
        b = orokit.analyze(dem, min_prominence_m=1.0, chunks=20, checkpoint=ck, scheduler="synchronous")
    assert len(calls) == 1  # only the damaged chunk
    _tables_equal(a, b)
    read_chunk(target)  # rewritten, readable again


def test_read_chunk_never_unpickles(tmp_path):
    p = tmp_path / "chunk_00000_00000.npz"
    with open(p, "wb") as fh:
        np.save(fh, np.array([object()], dtype=object), allow_pickle=True)
    with pytest.raises(TilingError, match="is corrupt"):
        read_chunk(p)


def test_cli_with_a_truncated_chunk(tmp_path, make_dem):
    from orokit.cli.main import cli

    z = np.random.default_rng(6).normal(size=(40, 40)).cumsum(0).cumsum(1) * 10 + 500
    tif = tmp_path / "d.tif"
    make_dem(z.astype("float32")).rio.to_raster(tif)
    ck = tmp_path / "ck"
    args = ["analyze", str(tif), "--chunks", "20", "--checkpoint", str(ck), "--no-progress", "--min-prominence", "5"]
    assert CliRunner().invoke(cli, args + ["-o", str(tmp_path / "a")]).exit_code == 0
    chunk = sorted(ck.glob("chunk_*.npz"))[0]
    chunk.write_bytes(chunk.read_bytes()[:100])
    from orokit.errors import OrokitWarning

    with pytest.warns(OrokitWarning, match="is corrupt .*recomputing that chunk"):
        res = CliRunner().invoke(cli, args + ["-o", str(tmp_path / "b")])
    assert res.exit_code == 0, res.output
    assert "Traceback" not in res.output and "Aborted" not in res.output
    assert (tmp_path / "a" / "peaks.csv").read_bytes() == (tmp_path / "b" / "peaks.csv").read_bytes()
