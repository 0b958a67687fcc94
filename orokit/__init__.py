"""orokit: measure mountains.

Peaks, key saddles, prominence, dominance, isolation and Divide Trees from elevation
rasters (exact, in memory or chunked with dask), orometric region classification,
and Divide Tree / terrain synthesis after Argudo et al. (2019),
doi:10.1145/3355089.3356535.

Heavy modules are imported lazily: ``import orokit`` is cheap.
"""
from __future__ import annotations

import importlib
from typing import Any

__version__ = "0.1.0"

# public name -> module that defines it
_LAZY = {
    "analyze": "orokit.analysis",
    "AnalysisResult": "orokit.topology.tables",
    "read_analysis": "orokit.analysis",
    "write_analysis": "orokit.analysis",
    "DivideTree": "orokit.topology.divide_tree",
    "read_dem": "orokit.io.dem",
}

__all__ = ["__version__", *_LAZY]


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'orokit' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)
