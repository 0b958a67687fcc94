"""Divide Tree synthesis from orometric terrain types (Argudo et al. 2019, section 5).

Public API (imported lazily)::

    TerrainType, load_terrain_type        # orokit.synthesis.terrain_type
    synthesize_divide_tree, SynthesisParams, peaks_table   # orokit.synthesis.tree
    compare_to_type                       # orokit.synthesis.fidelity
    edit                                  # editing operations (add/move/delete ...)

Writing a synthesized tree: :func:`orokit.io.synthesis_io.write_synthesis`.
"""
from __future__ import annotations

import importlib
from typing import Any

_LAZY = {
    "TerrainType": "orokit.synthesis.terrain_type",
    "load_terrain_type": "orokit.synthesis.terrain_type",
    "synthesize_divide_tree": "orokit.synthesis.tree",
    "SynthesisParams": "orokit.synthesis.tree",
    "peaks_table": "orokit.synthesis.tree",
    "compare_to_type": "orokit.synthesis.fidelity",
}

__all__ = [*_LAZY, "edit"]


def __getattr__(name: str) -> Any:
    if name == "edit":
        return importlib.import_module("orokit.synthesis.edit")
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'orokit.synthesis' has no attribute {name!r}")
