"""Two cores against one for ``orokit analyze``, from per-thread CPU (issue 13: >= 1.6x at 60 M cells).

On a shared machine the wall time of a 2-core run says little, so this measures what
does not depend on the other processes much: the CPU of every thread of the process.
It runs ``orokit -q analyze DEM -o OUT --no-progress [--no-isolation]`` twice, pinned to
one core (``NUMBA_NUM_THREADS=1``, ``taskset -c 0``) and to two, each in a process whose
hooks (installed as the modules load, so the import order is unchanged) note the
phases of the main thread and sample every thread's CPU (``/proc/self/task/*/schedstat``)
every 20 ms. For each window between two main-thread phase boundaries of the 2-core
run, the model's wall time is max(the busiest thread's CPU, all threads' CPU / 2), and
T2 is their sum; T1 is the CPU of the 1-core run. T1 / T2 is the ratio a quiet machine
would show if every thread ran whenever it had work: GIL waits, memory bandwidth shared
by two cores and GDAL/numba thread start-up are not in it (a C call that holds the GIL
shows as a thread that runs alone; see ``orokit.io.gdal_arrow``).

Run:  .venv/bin/python benchmarks/two_cores.py DEM.tif [--no-isolation] [--min-prominence 30.3276]
      (the 12 x 12 mosaic of ``vs_kirmse.py --tiles 12 --workdir W`` is W/mosaic_12x12/mosaic.tif)
"""
from __future__ import annotations

import argparse
import bisect
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: main-thread phases whose start and end cut the timeline into windows ("module:function")
PHASES = [
    "orokit.analysis:analyze", "orokit.io.dem:read_dem_array", "orokit.tiling.memory:release_library_pages",
    "orokit.topology.engine:saddle_graph", "orokit.topology.engine:_join_strips",
    "orokit.topology.engine:finalize_graph", "orokit.metrics.isolation:nearest_higher",
    "orokit.topology.engine:build_result", "orokit.io.analysis_io:write_analysis",
    "orokit.io.analysis_io:_write_csv", "orokit.io.analysis_io:_write_parquet",
]
NS = 1e9

_CHILD = r'''
import importlib.abc, importlib.machinery, json, os, resource, sys, threading, time
T0 = time.perf_counter()
OUT, TARGETS = sys.argv[1], json.loads(sys.argv[2])
EVENTS, SAMPLES = [], []


def snap():
    ru = resource.getrusage(resource.RUSAGE_SELF)
    out = {"_cpu": int((ru.ru_utime + ru.ru_stime) * 1e9)}
    for tid in os.listdir("/proc/self/task"):
        try:
            with open(f"/proc/self/task/{tid}/schedstat") as f:
                run, wait = f.read().split()[:2]
            out[tid] = int(run)
            out["q" + tid] = int(wait)
        except OSError:
            pass
    return out


def wrap(label, fn):
    def w(*a, **k):
        t0 = time.perf_counter()
        try:
            return fn(*a, **k)
        finally:
            EVENTS.append([label, threading.get_native_id(), t0 - T0, time.perf_counter() - T0])
    w.__wrapped__ = fn
    return w


class Finder(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name not in TARGETS:
            return None
        spec = importlib.machinery.PathFinder.find_spec(name, path)
        if spec is None or spec.loader is None:
            return spec
        orig = spec.loader.exec_module

        def exec_module(module):
            orig(module)
            for attr in TARGETS[name]:
                setattr(module, attr, wrap(f"{name}:{attr}", getattr(module, attr)))
        spec.loader.exec_module = exec_module
        return spec


def sampler():
    while True:
        SAMPLES.append([time.perf_counter() - T0, snap()])
        time.sleep(0.02)


def dump():
    SAMPLES.append([time.perf_counter() - T0, snap()])
    with open(OUT, "w") as f:
        json.dump({"main": threading.main_thread().native_id, "events": EVENTS, "samples": SAMPLES}, f)


import atexit
sys.meta_path.insert(0, Finder())
threading.Thread(target=sampler, name="sampler", daemon=True).start()
atexit.register(dump)
sys.argv = ["orokit", *sys.argv[3:]]
from orokit.cli.main import main
main()  # the console script: orokit's process settings, its exit
'''


def run(dem: Path, out: Path, cores: int, extra: list[str]) -> dict:
    """One ``orokit analyze`` pinned to ``cores`` cores under the hooks; its samples and phases, and
    ``process_s``: the process's wall time seen from here (with the interpreter's start and exit)."""
    targets: dict[str, list[str]] = {}
    for item in PHASES:
        module, attr = item.split(":")
        targets.setdefault(module, []).append(attr)
    with tempfile.TemporaryDirectory(prefix="orokit-two-cores-") as tmp:
        record = Path(tmp) / "run.json"
        env = dict(os.environ, NUMBA_NUM_THREADS=str(cores))
        cmd = ["taskset", "-c", f"0-{cores - 1}", sys.executable, "-c", _CHILD, str(record), json.dumps(targets),
               "-q", "analyze", str(dem), "-o", str(out), "--no-progress", "--overwrite", *extra]
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, env=env)
        t1 = time.perf_counter()
        rec = json.loads(record.read_text())
        rec["process_s"] = t1 - t0
        return rec


def model(rec: dict) -> tuple[float, float, list[tuple[str, float, float, float, float, float, float]]]:
    """(all threads' CPU, modelled 2-core wall, rows) of one run; a row: (window, wall, all threads' CPU,
    busiest thread's CPU, modelled wall, the main thread's CPU, the main thread's wait for a core)."""
    samples = rec["samples"]
    times = [s[0] for s in samples]
    main = str(rec["main"])
    cuts = {0.0: "start", samples[-1][0]: "end"}
    for label, tid, t0, t1 in rec["events"]:
        if str(tid) == main:
            short = label.split(":")[1]
            cuts.setdefault(t0, short + " >")
            cuts.setdefault(t1, short + " <")
    pts = sorted(cuts)

    def at(t: float) -> dict:
        return samples[max(0, bisect.bisect_right(times, t) - 1)][1]

    rows = []
    t2 = 0.0
    for a, b in zip(pts[:-1], pts[1:]):
        s0, s1 = at(a), at(b)
        per = {}
        for snap in [s[1] for s in samples[bisect.bisect_right(times, a):bisect.bisect_right(times, b)]] + [s1]:
            for tid, v in snap.items():  # a thread that ended inside the window: its last sample
                if tid.isdigit():
                    per[tid] = (v - s0.get(tid, 0)) / NS
        total = sum(per.values())
        busiest = max(per.values(), default=0.0)
        m = max(busiest, total / 2)
        t2 += m
        main_wait = (s1.get("q" + main, 0) - s0.get("q" + main, 0)) / NS
        rows.append((f"{cuts[a]} .. {cuts[b]}", b - a, total, busiest, m, per.get(main, 0.0), main_wait))
    return samples[-1][1]["_cpu"] / NS, t2, rows


def walls(one: dict, two: dict) -> list[tuple[str, ...]]:
    """The windows of both runs side by side (when their phases came in the same order); the rest
    (the interpreter's start before the hooks, its exit) as the row "process (outside the hooks)".
    A row: (window, 1-core wall, 1-core CPU, 2-core wall, 2-core CPU, 2-core busiest thread,
    2-core main thread's CPU, its wait for a core)."""
    _, _, r1 = model(one)
    _, _, r2 = model(two)
    if [r[0] for r in r1] != [r[0] for r in r2]:
        return []
    rows: list[tuple] = [(a[0], a[1], a[2], b[1], b[2], b[3], b[5], b[6]) for a, b in zip(r1, r2)]
    rest1 = one["process_s"] - sum(r[1] for r in r1)
    rest2 = two["process_s"] - sum(r[1] for r in r2)
    return rows + [("process (outside the hooks)", rest1, 0.0, rest2, 0.0, 0.0, 0.0, 0.0)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dem", type=Path)
    ap.add_argument("--no-isolation", action="store_true")
    ap.add_argument("--min-prominence", default="30.3276", help="metres (default: vs_kirmse.py's 99.5 ft)")
    ap.add_argument("--reps", type=int, default=1, help="pairs of runs (1 core, then 2 cores)")
    ap.add_argument("--json", type=Path, default=None, help="write the runs' figures here")
    args = ap.parse_args()
    extra = ["--min-prominence", args.min_prominence] + (["--no-isolation"] if args.no_isolation else [])
    results = []
    with tempfile.TemporaryDirectory(prefix="orokit-two-cores-out-") as tmp:
        for _ in range(args.reps):
            load = os.getloadavg()[0]
            one = run(args.dem, Path(tmp) / "one", 1, extra)
            two = run(args.dem, Path(tmp) / "two", 2, extra)
            t1, _, _ = model(one)
            cpu2, t2, rows = model(two)
            print(f"load {load:.1f}: 1 core {t1:.2f} CPU s; 2 cores {cpu2:.2f} CPU s, modelled wall {t2:.2f} s; "
                  f"ratio {t1 / t2:.2f}x; process wall {one['process_s']:.2f} / {two['process_s']:.2f} s: "
                  f"{one['process_s'] / two['process_s']:.2f}x (load {os.getloadavg()[0]:.1f} after)")
            side = walls(one, two)
            if side:
                print(f"  {'window':46s} {'wall 1':>6s} {'CPU 1':>6s} {'wall 2':>6s} {'CPU 2':>6s} {'busy 2':>6s} "
                      f"{'main 2':>6s} {'wait 2':>6s} {'idle 2':>6s}")
                for label, w1, c1, w2, c2, busiest, main_cpu, main_wait in side:
                    if w1 > 0.003 or w2 > 0.003:  # idle: the main thread neither ran nor waited for a core
                        print(f"  {label[:46]:46s} {w1:6.3f} {c1:6.3f} {w2:6.3f} {c2:6.3f} {busiest:6.3f} "
                              f"{main_cpu:6.3f} {main_wait:6.3f} {w2 - main_cpu - main_wait:6.3f}")
            else:
                print(f"  {'window (2 cores)':52s} {'wall':>6s} {'CPU s':>6s} {'busiest':>7s} {'model':>6s}")
                for label, wall, total, busiest, m, _, _ in rows:
                    if total > 0.005:
                        print(f"  {label[:52]:52s} {wall:6.3f} {total:6.3f} {busiest:7.3f} {m:6.3f}")
            results.append({"load": load, "t1_cpu_s": t1, "t2_cpu_s": cpu2, "t2_model_s": t2, "ratio": t1 / t2,
                            "process_s": [one["process_s"], two["process_s"]], "windows": rows, "walls": side})
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
