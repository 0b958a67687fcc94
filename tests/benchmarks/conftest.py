"""Make benchmarks/*.py importable from tests/benchmarks."""
from __future__ import annotations

import sys
from pathlib import Path

_bench = str(Path(__file__).resolve().parents[2] / "benchmarks")
if _bench not in sys.path:
    sys.path.insert(0, _bench)
