"""``benchmarks/corun.py``'s analysis: on-CPU intervals from a ``sched_switch`` trace, each strip's co-run
fraction, and the pooled slope of a strip's CPU against it (no perf needed: a hand-made trace)."""
from __future__ import annotations

import corun
import pytest


def _switch(cpu: int, t_us: int, prev: int, nxt: int) -> str:
    """One ``perf script -F comm,tid,cpu,time,event,trace`` line of ``sched:sched_switch`` at ``t_us`` microseconds."""
    return (f"python {prev} [{cpu:03d}] 100.{t_us:06d}: sched:sched_switch: prev_comm=python prev_pid={prev} "
            f"prev_prio=120 prev_state=R ==> next_comm=python next_pid={nxt} next_prio=120")


def test_co_run_fraction_of_each_strip():
    # thread 11 runs on CPU 0 from 0 to 400 us; thread 12 on CPU 1 from 100 to 200 us, then again from 300 to 600
    trace = [_switch(0, 0, 0, 11), _switch(1, 100, 0, 12), _switch(1, 200, 12, 0), _switch(1, 300, 0, 12),
             _switch(0, 400, 11, 0), _switch(1, 600, 12, 0)]
    spans = corun.on_cpu(trace)
    t = 100 * 10**9
    assert spans[11] == [(t, t + 400_000)]
    assert spans[12] == [(t + 100_000, t + 200_000), (t + 300_000, t + 600_000)]
    # a strip on 11 over its whole run: 200 of its 400 us beside 12; one on 12 from 300 to 600 us: 100 of 300
    record = [[11, 0, t, t + 400_000, 400_000, 0], [12, 5, t + 300_000, t + 600_000, 300_000, 0]]
    rows = corun.strips(record, spans)
    assert [r["corun"] for r in rows] == [pytest.approx(0.5), pytest.approx(1 / 3)]
    assert [r["cpu_ms"] for r in rows] == [0.4, 0.3]


def test_slope_pools_each_strips_deviations():
    # strip 0 costs 10 % more per 0.1 of co-run fraction, strip 5 the same around another mean: k = 1
    rows = [{"r0": 0, "rep": 0, "cpu_ms": 100.0, "corun": 0.0}, {"r0": 0, "rep": 1, "cpu_ms": 120.0, "corun": 0.2},
            {"r0": 5, "rep": 0, "cpu_ms": 220.0, "corun": 0.3}, {"r0": 5, "rep": 1, "cpu_ms": 180.0, "corun": 0.1}]
    assert corun.slope(rows) == pytest.approx(1.0, rel=0.1)
    # a strip's CPU that does not follow its fraction: k = 0
    flat = [dict(r, cpu_ms=100.0) for r in rows]
    assert corun.slope(flat) == 0.0
