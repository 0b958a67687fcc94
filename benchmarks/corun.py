"""What two strips running at once cost: the engine's strips' CPU against the time their threads ran together.

On a loaded machine a 2-core ``orokit analyze`` shows no more CPU than a 1-core one, while on a quiet one
it spent ~1.7 CPU s more (issue 13): its threads rarely run at the same time under load. This measures
that cost under load. ``saddle_graph`` runs ``--reps`` times (after one untimed run) on the raster with two numba threads under a
system-wide ``perf`` trace of ``sched:sched_switch`` (root); for every strip it notes its thread CPU and
the share of its run time during which the other strip thread ran too (its *co-run fraction*). Across the
repetitions the same strip runs with different fractions: the pooled slope of the strip's CPU (relative to
its own mean) against its fraction is ``k``, the extra CPU of a strip that ran beside the other all along
(one run's ``k`` is noisy at a 5 % co-run fraction: average several). Also prints the TLB flushes the strip
threads received (``tlb:tlb_flush`` by reason).

Run:  sudo .venv/bin/python benchmarks/corun.py DEM.tif [--reps 3]   (Linux, perf; the 12 x 12 mosaic of
      ``vs_kirmse.py --tiles 12 --workdir W`` is W/mosaic_12x12/mosaic.tif)
"""
from __future__ import annotations

import argparse
import collections
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

#: the child: orokit analyze's process settings, the raster read, ``saddle_graph`` with every strip timed
_CHILD = r'''
import json, os, sys, threading, time
import numpy as np
from orokit.cli.main import MMAP_THRESHOLD_BYTES, SWITCH_INTERVAL_S
from orokit.io.dem import read_dem_array
from orokit.tiling.memory import fix_mmap_threshold, limit_malloc_arenas
from orokit.topology import engine

limit_malloc_arenas(2); fix_mmap_threshold(MMAP_THRESHOLD_BYTES); sys.setswitchinterval(SWITCH_INTERVAL_S)
dem, reps, out = sys.argv[1], int(sys.argv[2]), sys.argv[3]
z = np.asarray(read_dem_array(dem).values)
engine.load_strip_kernels()
REC, REP = [], [0]
strip = engine._strip


def timed(z, r0, r1, ltype):
    t0, c0 = time.monotonic_ns(), time.thread_time_ns()
    try:
        return strip(z, r0, r1, ltype)
    finally:
        REC.append([threading.get_native_id(), r0, t0, time.monotonic_ns(), time.thread_time_ns() - c0, REP[0]])


engine.saddle_graph(z)  # untimed: the first run's first strips ran cold (page faults, caches)
engine._strip = timed
for REP[0] in range(reps):
    c0 = time.process_time()
    engine.saddle_graph(z)
    print(f"rep {REP[0]}: {time.process_time() - c0:.3f} CPU s, load {os.getloadavg()[0]:.1f}", flush=True)
json.dump(REC, open(out, "w"))
'''
_SWITCH = re.compile(r"\[(\d+)\]\s+(\d+)\.(\d+):\s+sched:sched_switch:.*prev_pid=(\d+).*next_pid=(\d+)")
_FLUSH = re.compile(r"^\s*\S+\s+(\d+)\s+\[\d+\]\s+\d+\.\d+:\s+tlb:tlb_flush:\s+pages:-?\d+ reason:(.*)$")


def _ns(sec: str, frac: str) -> int:
    return int(sec) * 10**9 + int(frac.ljust(9, "0")[:9])


def on_cpu(trace: list[str]) -> dict[int, list[tuple[int, int]]]:
    """Every task's on-CPU intervals (ns, CLOCK_MONOTONIC) from ``perf script`` lines of ``sched_switch``."""
    spans: dict[int, list[tuple[int, int]]] = collections.defaultdict(list)
    running: dict[int, tuple[int, int]] = {}
    for line in trace:
        m = _SWITCH.search(line)
        if m:
            cpu, t, prev, nxt = int(m.group(1)), _ns(m.group(2), m.group(3)), int(m.group(4)), int(m.group(5))
            if cpu in running and running[cpu][0] == prev:
                spans[prev].append((running[cpu][1], t))
            running[cpu] = (nxt, t)
    return spans


def _clip(spans: list[tuple[int, int]], a: int, b: int) -> list[tuple[int, int]]:
    return [(max(s, a), min(e, b)) for s, e in spans if e > a and s < b]


def strips(record: list[list[int]], spans: dict[int, list[tuple[int, int]]]) -> list[dict[str, float]]:
    """Per strip: its first row, repetition, thread CPU (ms) and co-run fraction."""
    tids = {r[0] for r in record}
    rows = []
    for tid, r0, t0, t1, cpu, rep in record:
        mine = _clip(spans[tid], t0, t1)
        run = sum(e - s for s, e in mine)
        both = sum(max(0, min(e, e2) - max(s, s2)) for other in tids - {tid}
                   for s2, e2 in _clip(spans[other], t0, t1) for s, e in mine)
        rows.append({"r0": r0, "rep": rep, "cpu_ms": cpu / 1e6, "corun": both / max(run, 1)})
    return rows


def slope(rows: list[dict[str, float]]) -> float:
    """Pooled slope of a strip's CPU relative to its own mean against its co-run fraction (deviations from
    each strip's means over the repetitions)."""
    by: dict[float, list[dict[str, float]]] = collections.defaultdict(list)
    for r in rows:
        by[r["r0"]].append(r)
    xs, ys = [], []
    for group in by.values():
        if len(group) > 1:
            mc = statistics.mean(r["cpu_ms"] for r in group)
            mf = statistics.mean(r["corun"] for r in group)
            xs += [r["corun"] - mf for r in group]
            ys += [(r["cpu_ms"] - mc) / mc for r in group]
    return sum(x * y for x, y in zip(xs, ys)) / max(sum(x * x for x in xs), 1e-12)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dem", type=Path)
    ap.add_argument("--reps", type=int, default=3)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="orokit-corun-") as tmp:
        rec, data = Path(tmp) / "strips.json", Path(tmp) / "perf.data"
        env = dict(os.environ, NUMBA_NUM_THREADS="2")
        subprocess.run(["perf", "record", "-a", "-q", "-k", "CLOCK_MONOTONIC", "-e", "sched:sched_switch", "-e",
                        "tlb:tlb_flush", "-o", str(data), "--", sys.executable, "-c", _CHILD, str(args.dem),
                        str(args.reps), str(rec)], check=True, env=env)
        trace = subprocess.run(["perf", "script", "-i", str(data), "-F", "comm,tid,cpu,time,event,trace"],
                               check=True, capture_output=True, text=True).stdout.splitlines()
        record = json.loads(rec.read_text())
    rows = strips(record, on_cpu(trace))
    tids = {r[0] for r in record}
    flushes = collections.Counter(m.group(2).strip() for m in map(_FLUSH.search, trace)
                                  if m and int(m.group(1)) in tids)
    print(f"{len(rows)} strips: co-run fraction mean {statistics.mean(r['corun'] for r in rows):.3f} (max "
          f"{max(r['corun'] for r in rows):.3f}), strip CPU mean {statistics.mean(r['cpu_ms'] for r in rows):.1f} ms; "
          f"k = {slope(rows):.3f} (a strip run beside the other all along: 1 + k times the CPU)")
    print("TLB flushes on the strip threads:", dict(flushes))


if __name__ == "__main__":
    main()
