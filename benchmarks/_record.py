"""Store a benchmark's measurements as JSON under reports/benchmarks/ (with the machine load)."""
from __future__ import annotations

import datetime
import json
import os
import platform
from pathlib import Path

OUT = Path(__file__).resolve().parents[1] / "reports" / "benchmarks"


def record(name: str, results: dict) -> Path:
    """Write ``reports/benchmarks/<name>.json`` atomically and return its path."""
    from orokit import __version__
    from orokit.io.atomic import write_text_atomic

    doc = {
        "benchmark": name,
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "orokit_version": __version__,
        "machine": {"cpus": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version()},
        "load_average_1_5_15": list(os.getloadavg()),
        "results": results,
    }
    OUT.mkdir(parents=True, exist_ok=True)
    return write_text_atomic(OUT / f"{name}.json", json.dumps(doc, indent=1, default=float))
