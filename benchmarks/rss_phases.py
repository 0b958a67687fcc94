"""Resident memory of one ``orokit`` process by phase (issue 13: peak RSS <= Kirmse's).

Runs ``orokit ARGS...`` in this process (the console script's ``main()``, so the process
settings are those of ``orokit``) with a sampler thread that reads ``/proc/self/status``
(VmRSS, RssAnon, RssFile) every 4 ms and names the phase by the innermost function of the
main thread's stack among :data:`PHASES` (no hook: the import order is unchanged). At each
phase's new high (+3 MB) it also reads ``/proc/self/smaps`` and keeps the largest mappings.
Prints, by phase in time order, the highest RSS with its anonymous and file parts; the
whole record (phases, mappings, a sample every 20 ms) goes to OUT.json.

The sampler holds the GIL a few microseconds per sample and reads smaps a few dozen
times (~1-3 ms each): the timings it sees are not the program's; its memory is (a few
hundred kB of samples).

``--libraries``: instead, the resident memory of the libraries ``orokit analyze`` holds at
once while writing, imported one after the other in a fresh process with the settings of
``orokit analyze`` (two malloc arenas, Arrow on malloc, LLVM's pages dropped): the floor of
the writing phase, with no data.

Run:  .venv/bin/python benchmarks/rss_phases.py OUT.json -q analyze DEM.tif -o OUT --no-progress [--no-isolation]
      .venv/bin/python benchmarks/rss_phases.py --libraries
"""
from __future__ import annotations

import json
import sys
import threading
import time

#: phases ("module:function"), innermost first: the first found on the main thread's stack names the sample
PHASES = ["orokit.io.analysis_io:_write_csv", "orokit.io.analysis_io:_write_parquet", "orokit.io.analysis_io:_write",
          "orokit.topology.engine:build_result", "orokit.metrics.isolation:finish_isolation",
          "orokit.metrics.isolation:nearest_higher", "orokit.topology.engine:finalize_graph",
          "orokit.topology.engine:saddle_graph", "orokit.tiling.summary:finalize_summary",
          "orokit.tiling.summary:merge_summaries", "orokit.tiling.summary:chunk_summary",
          "orokit.io.dem:read_dem_array", "orokit.analysis:analyze", "orokit.cli.analyze:analyze", "orokit.cli.main:main"]
#: seconds between two samples
STEP = 0.004


def status() -> dict[str, int]:
    """VmRSS, RssAnon, RssFile of this process in MiB."""
    out = {}
    with open("/proc/self/status") as f:
        for line in f:
            key, _, value = line.partition(":")
            if key in ("VmRSS", "RssAnon", "RssFile"):
                out[key] = int(value.split()[0]) // 1024
    return out


def mappings(top: int = 20) -> list[tuple[int, str]]:
    """The ``top`` largest resident mappings (MiB, file name or [anon]/[heap]), summed by name."""
    sizes: dict[str, int] = {}
    name = "?"
    with open("/proc/self/smaps") as f:
        for line in f:
            parts = line.split()
            if not parts[0].endswith(":"):
                name = parts[5].rsplit("/", 1)[-1] if len(parts) > 5 else "[anon]"
            elif parts[0] == "Rss:":
                sizes[name] = sizes.get(name, 0) + int(parts[1])
    return sorted(((kb // 1024, n) for n, kb in sizes.items() if kb >= 1024), reverse=True)[:top]


class Sampler:
    """Samples of this process's memory, named by the main thread's phase (during the writing the
    main thread writes the CSV and Parquet files, then waits in ``_write`` for the GeoPackage's thread)."""

    def __init__(self) -> None:
        self.main = threading.get_ident()
        self.samples: list[dict] = []
        self.highs: dict[str, dict] = {}
        self.stop = False
        self.t0 = time.perf_counter()

    def phase(self) -> str:
        frame = sys._current_frames().get(self.main)
        names = set()
        while frame is not None:
            names.add(f"{frame.f_globals.get('__name__')}:{frame.f_code.co_name}")
            frame = frame.f_back
        found = next((p for p in PHASES if p in names), "start")
        return found.rsplit(".", 1)[-1]  # the module's last name and the function: "engine:saddle_graph"

    def run(self) -> None:
        while not self.stop:
            s: dict = status()
            s["t"] = round(time.perf_counter() - self.t0, 3)
            s["phase"] = self.phase()
            self.samples.append(s)
            high = self.highs.setdefault(s["phase"], {"VmRSS": 0, "mapped_at": 0})
            if s["VmRSS"] > high["VmRSS"]:
                high.update(s)
                if s["VmRSS"] > high["mapped_at"] + 3:
                    high["mapped_at"] = s["VmRSS"]
                    high["mappings"] = mappings()
            time.sleep(STEP)

    def report(self, path: str) -> None:
        self.stop = True
        with open(path, "w") as f:
            json.dump({"phases": self.highs, "samples": self.samples[::5]}, f)
        peak = max(self.samples, key=lambda s: s["VmRSS"])
        print(f"peak RSS {peak['VmRSS']} MiB in {peak['phase']} (t {peak['t']:.2f} s)", file=sys.stderr)
        for name, h in sorted(self.highs.items(), key=lambda kv: kv[1]["t"]):
            print(f"  {name:24s} {h['VmRSS']:5d} MiB  anonymous {h['RssAnon']:4d}  file {h['RssFile']:4d}"
                  f"  (t {h['t']:.2f} s)", file=sys.stderr)


def libraries() -> None:
    """Print the resident memory after each library ``orokit analyze`` has loaded by its writing phase."""
    import os

    from orokit.cli.main import apply_process_settings

    apply_process_settings("analyze")

    def show(what: str) -> None:
        s = status()
        print(f"{what:44s} {s['VmRSS']:4d} MiB  anonymous {s['RssAnon']:4d}  file {s['RssFile']:4d}")

    print(f"ARROW_DEFAULT_MEMORY_POOL={os.environ.get('ARROW_DEFAULT_MEMORY_POOL')}")
    show("python, orokit.cli.main")
    import numpy  # noqa: F401

    show("+ numpy")
    import rasterio  # noqa: F401

    show("+ rasterio (its GDAL)")
    import pyproj  # noqa: F401

    show("+ pyproj")
    from orokit.analysis import load_kernels
    from orokit.cli.analyze import _numba_without_blas_probe

    _numba_without_blas_probe()
    load_kernels(isolation=True)
    show("+ numba, the engine's and isolation's kernels")
    from orokit.tiling.memory import release_library_pages

    release_library_pages("libllvmlite")
    show("  LLVM's pages dropped (as orokit analyze)")
    import pyarrow.csv  # noqa: F401
    import pyarrow.parquet  # noqa: F401

    show("+ pyarrow (csv, parquet)")
    import pandas  # noqa: F401

    show("+ pandas")
    import pyogrio  # noqa: F401

    show("+ pyogrio (its GDAL)")
    import geopandas  # noqa: F401

    show("+ geopandas, shapely")


def main() -> None:
    if sys.argv[1:] == ["--libraries"]:
        libraries()
        return
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    import atexit

    sampler = Sampler()
    atexit.register(sampler.report, sys.argv[1])  # orokit's exit runs the exit handlers, then leaves
    threading.Thread(target=sampler.run, name="rss-sampler", daemon=True).start()
    sys.argv = ["orokit", *sys.argv[2:]]
    from orokit.cli.main import main as orokit_main

    orokit_main()


if __name__ == "__main__":
    main()
