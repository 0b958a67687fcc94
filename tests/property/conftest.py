"""Make the oracle module importable from tests/topology and tests/property."""
from __future__ import annotations

import sys
from pathlib import Path

_here = str(Path(__file__).resolve().parents[1] / "topology")
if _here not in sys.path:
    sys.path.insert(0, _here)
