"""Fetching into the cache from a mirror or URL: hash checks, atomicity, CLI."""
from __future__ import annotations

import hashlib
import importlib
import shutil
from pathlib import Path

import pytest
import yaml
from click.testing import CliRunner

from orokit.cli.main import cli
from orokit.data import fetch, fetch_file, load_manifest, verify
from orokit.errors import DataError

fetch_mod = importlib.import_module("orokit.io.fetch")  # the package re-exports a function named fetch

FILES = {"dems/a.txt": b"alpha " * 1000, "dems/b.bin": bytes(range(256)) * 64, "shared/LICENSE": b"MIT\n"}


@pytest.fixture
def env(tmp_path, monkeypatch):
    """A temporary mirror, manifest and cache, wired through the environment."""
    mirror, cache = tmp_path / "mirror", tmp_path / "cache"
    for rel, data in FILES.items():
        (mirror / rel).parent.mkdir(parents=True, exist_ok=True)
        (mirror / rel).write_bytes(data)

    def entry(rel):
        return {"path": rel, "url": f"https://example.invalid/{rel}", "sha256": hashlib.sha256(FILES[rel]).hexdigest(),
                "size": len(FILES[rel])}

    common = {"kind": "dem", "format": "txt", "z_units": "m", "crs": "EPSG:32633", "licence": "MIT", "citation": "c"}
    doc = {"version": 1, "datasets": [
        {"name": "a", **common, "files": [entry("dems/a.txt"), entry("shared/LICENSE")]},
        {"name": "b", **common, "files": [entry("dems/b.bin"), entry("shared/LICENSE")]},
    ]}
    man_path = tmp_path / "datasets.yaml"
    man_path.write_text(yaml.safe_dump(doc))
    monkeypatch.setenv("OROKIT_MANIFEST", str(man_path))
    monkeypatch.setenv("OROKIT_DATA_DIR", str(cache))
    monkeypatch.setenv("OROKIT_DATA_MIRROR", str(mirror))
    return mirror, cache, load_manifest()


def _leftovers(root: Path) -> list[str]:
    return sorted(p.name for p in root.rglob("*") if p.is_file() and ".tmp-" in p.name)


def test_fetch_from_mirror_and_cache_hit(env):
    mirror, cache, man = env
    out = fetch(manifest=man)
    assert out["a"][0] == cache / "dems/a.txt" and out["a"][0].read_bytes() == FILES["dems/a.txt"]
    assert out["b"][1] == cache / "shared/LICENSE"
    mtime = (cache / "dems/a.txt").stat().st_mtime_ns
    (mirror / "dems/a.txt").unlink()  # a cache hit does not need the mirror any more
    assert fetch(["a"], manifest=man)["a"][0].stat().st_mtime_ns == mtime
    assert all(r.status == "ok" for r in verify(manifest=man))
    assert _leftovers(cache) == []


def test_wrong_hash_names_file_and_both_hashes(env):
    mirror, cache, man = env
    (mirror / "dems/b.bin").write_bytes(b"tampered")
    expected = hashlib.sha256(FILES["dems/b.bin"]).hexdigest()
    actual = hashlib.sha256(b"tampered").hexdigest()
    with pytest.raises(DataError) as info:
        fetch(["b"], manifest=man)
    msg = str(info.value)
    assert "dems/b.bin" in msg and expected in msg and actual in msg
    assert not (cache / "dems/b.bin").exists() and _leftovers(cache) == []


def test_bad_copy_keeps_old_good_file(env):
    mirror, cache, man = env
    fetch(["b"], manifest=man)
    (mirror / "dems/b.bin").write_bytes(b"tampered")
    with pytest.raises(DataError, match="sha256 mismatch"):
        fetch(["b"], manifest=man, force=True)
    assert (cache / "dems/b.bin").read_bytes() == FILES["dems/b.bin"]


def test_interrupted_copy_leaves_no_partial_file(env, monkeypatch):
    mirror, cache, man = env

    def half_then_die(fin, fout, length=0):
        fout.write(fin.read(100))
        raise KeyboardInterrupt("killed mid-copy")

    monkeypatch.setattr(shutil, "copyfileobj", half_then_die)
    with pytest.raises(KeyboardInterrupt):
        fetch(["a"], manifest=man)
    assert not (cache / "dems/a.txt").exists() and _leftovers(cache) == []
    monkeypatch.undo()
    monkeypatch.setenv("OROKIT_DATA_DIR", str(cache))
    monkeypatch.setenv("OROKIT_DATA_MIRROR", str(mirror))
    assert fetch(["a"], manifest=man)["a"][0].read_bytes() == FILES["dems/a.txt"]  # rerun recovers


def test_corrupt_cached_file_is_refetched(env):
    mirror, cache, man = env
    fetch(["a"], manifest=man)
    (cache / "dems/a.txt").write_bytes(b"bit rot")
    assert [r.status for r in verify(["a"], manifest=man)] == ["mismatch", "ok"]
    fetch(["a"], manifest=man)
    assert (cache / "dems/a.txt").read_bytes() == FILES["dems/a.txt"]


def test_missing_in_mirror(env):
    mirror, cache, man = env
    (mirror / "dems/a.txt").unlink()
    with pytest.raises(DataError, match="not in the data mirror"):
        fetch(["a"], manifest=man)
    assert [r.status for r in verify(["a"], manifest=man)] == ["missing", "missing"]


def test_download_path_checks_hash(env, monkeypatch):
    mirror, cache, man = env
    monkeypatch.delenv("OROKIT_DATA_MIRROR")
    entry = man["a"].files[0]

    def fake_download(url, dst, retries=3):
        assert url == entry.url
        Path(dst).write_bytes(b"served something else")

    monkeypatch.setattr(fetch_mod, "_download", fake_download)
    with pytest.raises(DataError, match="example.invalid"):
        fetch_file(entry)
    assert not (cache / entry.path).exists()

    monkeypatch.setattr(fetch_mod, "_download", lambda url, dst, retries=3: Path(dst).write_bytes(FILES[entry.path]))
    assert fetch_file(entry).read_bytes() == FILES[entry.path]


def test_cli_list_fetch_verify(env):
    mirror, cache, man = env
    runner = CliRunner()
    res = runner.invoke(cli, ["data", "list"])
    assert res.exit_code == 0, res.output
    assert "a " in res.output and "0/2" in res.output
    res = runner.invoke(cli, ["-q", "data", "verify"])
    assert res.exit_code == 1 and "MISSING" in res.output and "failed verification" in res.output
    res = runner.invoke(cli, ["data", "fetch", "--no-progress", "a"])
    assert res.exit_code == 0, res.output
    assert (cache / "dems/a.txt").exists() and not (cache / "dems/b.bin").exists()
    res = runner.invoke(cli, ["data", "fetch", "--no-progress"])
    assert res.exit_code == 0 and "2 dataset(s), 3 file(s)" in res.output  # a shared file counts once
    res = runner.invoke(cli, ["data", "verify"])
    assert res.exit_code == 0 and "all 3 file(s) verified" in res.output
    res = runner.invoke(cli, ["data", "path", "b"])
    assert res.exit_code == 0 and res.output.strip() == str(cache / "dems/b.bin")
    res = runner.invoke(cli, ["data", "fetch", "nope"])
    assert res.exit_code == 1 and "unknown dataset 'nope'" in res.output
    (cache / "dems/b.bin").write_bytes(b"x")
    res = runner.invoke(cli, ["data", "verify", "b"])
    assert res.exit_code == 1 and "MISMATCH" in res.output
