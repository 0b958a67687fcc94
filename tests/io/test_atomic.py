"""Atomic writes: a failure mid-write never leaves a partial file under the final name."""
from __future__ import annotations

import pytest

from orokit.errors import OrokitError
from orokit.io.atomic import atomic_open, atomic_path, temp_path_for, write_bytes_atomic, write_text_atomic


def test_success_replaces_and_cleans(tmp_path):
    final = tmp_path / "sub" / "out.gpkg"
    with atomic_path(final) as tmp:
        assert tmp.parent == final.parent and tmp.suffix == ".gpkg" and not tmp.exists()
        assert not final.exists()  # nothing visible under the final name while writing
        tmp.write_bytes(b"new")
    assert final.read_bytes() == b"new"
    assert sorted(p.name for p in final.parent.iterdir()) == ["out.gpkg"]


def test_exception_mid_write_keeps_old_file(tmp_path):
    final = tmp_path / "table.csv"
    final.write_text("old,good\n")
    with pytest.raises(RuntimeError, match="boom"):
        with atomic_open(final, "w") as fh:
            fh.write("new,half")
            raise RuntimeError("boom")
    assert final.read_text() == "old,good\n"
    assert [p.name for p in tmp_path.iterdir()] == ["table.csv"]


def test_exception_leaves_no_final_file(tmp_path):
    final = tmp_path / "x.bin"
    with pytest.raises(KeyboardInterrupt):
        with atomic_path(final) as tmp:
            tmp.write_bytes(b"partial")
            raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []


def test_temporary_directory_removed_on_error(tmp_path):
    with pytest.raises(ValueError):
        with atomic_path(tmp_path / "out.zarr") as tmp:
            (tmp / "a").mkdir(parents=True)
            raise ValueError
    assert list(tmp_path.iterdir()) == []


def test_nothing_written_is_an_error(tmp_path):
    with pytest.raises(OrokitError, match="nothing was written"):
        with atomic_path(tmp_path / "never.txt"):
            pass
    assert list(tmp_path.iterdir()) == []


def test_helpers(tmp_path):
    assert write_text_atomic(tmp_path / "a.txt", "héllo\n").read_text(encoding="utf-8") == "héllo\n"
    assert write_bytes_atomic(tmp_path / "b.bin", b"\x00\x01").read_bytes() == b"\x00\x01"
    a, b = temp_path_for(tmp_path / "c.tif"), temp_path_for(tmp_path / "c.tif")
    assert a != b and a.name.startswith(".c.tif.tmp-") and a.suffix == ".tif"
    with pytest.raises(ValueError, match="write mode"):
        with atomic_open(tmp_path / "r.txt", "r"):
            pass
