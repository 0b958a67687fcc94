"""Fuzzing the parsers orokit owns: terrain-type JSON and the reference TXT Divide Tree.

Truncation at every byte and random byte mutations of a small valid file give either a
valid result or one of the documented errors (never another exception, never a hang).
"""
from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from orokit.errors import DivideTreeError, InputError, SchemaError, UnitsError
from orokit.io.divide_tree_io import read_divide_tree_txt, write_divide_tree_txt
from orokit.synthesis.terrain_type import TerrainType, loads_terrain_type
from orokit.topology.divide_tree import DivideTree

TYPE_ERRORS = (SchemaError, InputError, UnitsError)
TREE_ERRORS = (InputError, DivideTreeError)


def _small_type_bytes() -> bytes:
    rng = np.random.default_rng(0)
    n = 60
    z = rng.uniform(300, 2500, n)
    x, y = rng.uniform(0, 10_000, n), rng.uniform(0, 10_000, n)
    ang = rng.uniform(0, 2 * np.pi, n)
    import pandas as pd

    peaks = pd.DataFrame({"x": x, "y": y, "elevation": z, "prominence": np.minimum(30 + rng.exponential(100, n), z),
                          "saddle_x": x + 300 * np.cos(ang), "saddle_y": y + 300 * np.sin(ang)})
    top = int(np.argmax(z))
    peaks.loc[top, ["saddle_x", "saddle_y"]] = np.nan
    peaks.loc[top, "prominence"] = z[top]
    t = TerrainType.from_peaks(peaks, area_km2=100.0, name="fuzz")
    return json.dumps(t.to_dict(), separators=(",", ":")).encode()


TYPE_BYTES = _small_type_bytes()


def _small_tree_bytes(tmp_path_factory) -> bytes:
    tree = DivideTree.from_arrays(
        [[1.5 * 92.61, -0.5 * 92.61, 1000.0], [5.5 * 92.61, -2.5 * 92.61, 900.0], [8.5 * 92.61, -6.5 * 92.61, 950.0],
         [2.5 * 92.61, -8.5 * 92.61, 700.0]],
        [[3.5 * 92.61, -1.5 * 92.61, 800.0], [7.5 * 92.61, -4.5 * 92.61, 850.0], [2.5 * 92.61, -5.5 * 92.61, 600.0]],
        [[0, 1, 0], [1, 2, 1], [0, 3, 2]], crs=None)
    p = tmp_path_factory.mktemp("fuzz") / "tree.txt"
    write_divide_tree_txt(tree, p, height=10, cell_size_m=92.61)
    return p.read_bytes()


@pytest.fixture(scope="module")
def tree_bytes(tmp_path_factory):
    data = _small_tree_bytes(tmp_path_factory)
    p = tmp_path_factory.mktemp("ok") / "t.txt"
    p.write_bytes(data)
    assert read_divide_tree_txt(p).n_peaks == 4  # the seed file is valid
    return data


def _parse_type(data: bytes):
    try:
        return loads_terrain_type(data, source="fuzz.json")
    except TYPE_ERRORS as exc:
        assert "fuzz.json" in str(exc) or str(exc)  # a message, not an empty error
        return None


def _parse_tree(path, data: bytes):
    path.write_bytes(data)
    try:
        return read_divide_tree_txt(path)
    except TREE_ERRORS as exc:
        assert str(exc)
        return None


def test_type_seed_file_is_valid():
    assert loads_terrain_type(TYPE_BYTES).name == "fuzz"


def test_type_truncated_at_every_byte():
    results = [_parse_type(TYPE_BYTES[:i]) for i in range(len(TYPE_BYTES))]
    assert all(r is None for r in results)  # any strict prefix of the JSON object is refused


def test_tree_truncated_at_every_byte(tree_bytes, tmp_path):
    p = tmp_path / "cut.txt"
    n_ok = 0
    for i in range(len(tree_bytes)):
        tree = _parse_tree(p, tree_bytes[:i])
        if tree is not None:
            n_ok += 1
            tree.validate()
    assert n_ok < len(tree_bytes) // 2  # most prefixes are refused, the rest are valid trees


_mutation = st.lists(st.tuples(st.integers(min_value=0), st.integers(0, 255)), min_size=1, max_size=8)


def _mutate(data: bytes, edits) -> bytes:
    b = bytearray(data)
    for pos, val in edits:
        b[pos % len(b)] = val
    return bytes(b)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(edits=_mutation)
def test_type_with_mutated_bytes(edits):
    t = _parse_type(_mutate(TYPE_BYTES, edits))
    if t is not None:  # a mutation that still parses is a valid type
        assert t.peak_density_per_km2 > 0


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(edits=_mutation, data=st.data())
def test_tree_with_mutated_bytes(tree_bytes, tmp_path, edits, data):
    tree = _parse_tree(tmp_path / "m.txt", _mutate(tree_bytes, edits))
    if tree is not None:
        tree.validate()  # whatever the reader accepts is a valid tree


@settings(max_examples=200, deadline=None)
@given(blob=st.binary(max_size=400))
def test_random_bytes_are_refused_cleanly(blob):
    _parse_type(blob)
