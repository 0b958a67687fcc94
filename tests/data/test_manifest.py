"""The datasets manifest: content, validation, and hashes against the real-data mirror."""
from __future__ import annotations

import textwrap

import pytest

from orokit.data import load_manifest, sha256_file, verify
from orokit.errors import DataError

PNG_DEMS = {
    "alaska", "andes-aconcagua", "andes-chile", "appalachians", "gobi", "highlands", "himalaya-annapurna",
    "himalaya-everest", "karakoram", "norway", "pyrenees", "rockies", "sahara",
}


def test_manifest_describes_every_dataset():
    man = load_manifest()
    assert PNG_DEMS <= set(man.names)
    assert "pysheds-dem" in man and "regions" in man
    for name in PNG_DEMS:
        ds = man[name]
        assert ds.kind == "dem" and ds.format == "png16" and ds.z_units == "ft" and ds.local_grid
        assert ds.cell_size_m == (30.87 if name == "pyrenees" else 92.61)  # 1 arcsec = 30.87 m (paper scripts)
        roles = sorted(f.role for f in ds.files)
        assert roles == ["dem", "divide_tree", "licence"]
        assert ds.primary.path == f"dems/{name}.png" and "c85d6ca" in ds.primary.url
        assert ds.licence and "doi:10.1145/3355089.3356535" in ds.citation and "Ferranti" in ds.citation
        assert ds.region
    geo = man["pysheds-dem"]
    assert geo.crs == "EPSG:4326" and geo.z_units == "m" and not geo.local_grid
    regions = man["regions"]
    shp = regions.files_with_role("shape")
    assert len(shp) == 50 and len({f.region for f in regions.files}) == 50
    for region in {f.region for f in regions.files}:
        assert sorted(f.filename.rsplit(".", 1)[1] for f in regions.files if f.region == region) == [
            "dbf", "kml", "prj", "shp", "shx"]
    # every DEM's region label is one of the 50 polygons
    assert {man[n].region for n in PNG_DEMS} <= {f.region for f in regions.files}


def test_find_file():
    man = load_manifest()
    assert man.find_file("alaska")[1].path == "dems/alaska.png"
    assert man.find_file("dems/alaska.txt")[1].role == "divide_tree"
    assert man.find_file("alps.shp")[0].name == "regions"
    with pytest.raises(DataError, match="neither"):
        man.find_file("atlantis")
    with pytest.raises(DataError, match="unknown dataset 'atlantis'"):
        man["atlantis"]


@pytest.mark.realdata
def test_every_manifest_hash_matches_the_mirror(data_mirror):
    man = load_manifest()
    results = verify(manifest=man, root=data_mirror)
    assert len(results) == len(man.unique_files()) == 279
    bad = [(r.path, r.status) for r in results if r.status != "ok"]
    assert not bad, bad
    # sizes too
    for f in man.unique_files():
        assert (data_mirror / f.path).stat().st_size == f.size


GOOD = """\
version: 1
datasets:
- name: tiny
  kind: dem
  format: geotiff
  z_units: m
  crs: EPSG:32633
  licence: CC0
  citation: nobody
  files:
  - path: tiny/tiny.tif
    url: https://example.invalid/tiny.tif
    sha256: {sha}
"""


@pytest.mark.parametrize(
    "mutate, match",
    [
        (lambda s: s.replace("version: 1", "version: 7"), "version"),
        (lambda s: s.replace("  licence: CC0\n", ""), "licence"),
        (lambda s: s.replace("a" * 64, "xyz"), "64 hex"),
        (lambda s: s.replace("path: tiny/tiny.tif", "path: ../etc/passwd"), "relative"),
        (lambda s: s.replace("  z_units: m\n", ""), "z_units"),
        (lambda s: s + s.split("datasets:\n", 1)[1], "twice"),
        (lambda s: s.replace("crs: EPSG:32633", "crs: local grid"), "cell_size_m"),
        (lambda s: "datasets: [unclosed", "parse"),
    ],
)
def test_invalid_manifests(tmp_path, mutate, match):
    p = tmp_path / "m.yaml"
    p.write_text(GOOD.format(sha="a" * 64))
    assert load_manifest(p)["tiny"].files[0].sha256 == "a" * 64
    p.write_text(mutate(GOOD.format(sha="a" * 64)))
    with pytest.raises(DataError, match=match):
        load_manifest(p)


def test_missing_manifest(tmp_path, monkeypatch):
    monkeypatch.setenv("OROKIT_MANIFEST", str(tmp_path / "none.yaml"))
    with pytest.raises(DataError, match="OROKIT_MANIFEST"):
        load_manifest()


def test_sha256_file(tmp_path):
    p = tmp_path / "x"
    p.write_bytes(b"abc")
    assert sha256_file(p) == "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
