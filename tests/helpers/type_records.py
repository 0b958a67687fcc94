"""Checks shared by the tests of a terrain type's optional records (saddle level, plain dominance, ...)."""
from __future__ import annotations

import dataclasses
from typing import Any

import pytest

from orokit.errors import SchemaError
from orokit.synthesis.terrain_type import TerrainType


def check_optional_record(t: TerrainType, name: str, bad: Any, *, shift_keeps: bool = True) -> None:
    """``name`` survives the JSON round trip, a type written without it loads with None, ``bad`` is refused
    naming it, and (``shift_keeps``) an elevation shift keeps it."""
    assert getattr(TerrainType.from_dict(t.to_dict()), name) == getattr(t, name)
    old = t.to_dict()
    del old[name]  # a type written before the record
    assert getattr(TerrainType.from_dict(old), name) is None
    with pytest.raises(SchemaError, match=name):
        dataclasses.replace(t, **{name: bad})
    if shift_keeps:
        assert getattr(t.shifted("elevation", 300.0), name) == getattr(t, name)
