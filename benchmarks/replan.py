"""The receding-plan motion computer ``replan`` (:class:`~cogblocks.sync.receding.RecedingPlanMotion`): does a decision
fit its period, inline and live?

* ``replan.<group>.decide_p50_s`` / ``_p99_s`` / ``_max_s``: CPU seconds of one decision (``decide_ms``), simulated
  inline; reference: the decision period (``decide_every``), the time a decision has on its worker thread live.
* ``replan.<group>.r``: r with ``replan``; reference: r without L2, measured in the same run.
* ``replan.<group>.live_late``: decisions late in a real-time run at 100 Hz with ``worker="thread"`` (the trial
  cut to ``LIVE_S``); reference: decisions made, so ``ratio`` is the late share.
* ``replan.<group>.live_tick_p99_ms``: the 99th percentile of the wall time of a tick of that run, the decision
  thread running beside it; reference: the same for ``mean`` in the same run.

Groups: those of :mod:`benchmarks.bound` (Table 2's group 1 and the first three of the *validation* split) and the
largest of the first 20 validation groups (N = 15, all-to-all); ``quick`` cuts every group to at most 20 s.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Iterator

import numpy as np

from benchmarks.bound import plain_runs
from cogblocks.data.groups import SyncGroup, random_groups
from cogblocks.diagrams.sync import MOTIONS, pop_sync
from cogblocks.sim import Simulator
from cogblocks.sync import RecedingPlanMotion

#: Seconds of each real-time run (``quick``: 10).
LIVE_S = 30.0


def _groups(quick: bool) -> Iterator[tuple[str, SyncGroup, int, float]]:
    yield from ((label, g, n_steps, r0) for label, g, n_steps, r0, _ in plain_runs(quick))
    largest = max(random_groups(20, "validation", 0), key=lambda g: (g.n, g.graph_kind == "all"))
    if quick:
        largest = dataclasses.replace(largest, duration=min(largest.duration, 20.0))
    n_steps = round(largest.duration / 0.01) + 1
    yield "largest", largest, n_steps, float(Simulator(pop_sync(largest, l2=False)).run(n_steps=n_steps)["r"].mean())


def _live(group: SyncGroup, motion: object, seconds: float) -> tuple[object, float]:
    """A real-time run of ``seconds`` at 100 Hz: the report and its p99 tick (ms)."""
    from cogblocks.live import run_realtime

    d = pop_sync(dataclasses.replace(group, duration=seconds), motion=motion)
    report = run_realtime(d.compile(0.01), seconds)
    return report, float(np.percentile(report.tick_ms, 99))


def run(quick: bool = False) -> Iterator[dict]:
    """Yield decision costs against the period, r against no L2, and late decisions of a live run."""
    live_s = 10.0 if quick else LIVE_S
    for label, group, n_steps, r0 in _groups(quick):
        block = MOTIONS["replan"](group)
        r = float(Simulator(pop_sync(group, motion=block)).run(n_steps=n_steps)["r"].mean())
        period = block.decide_ticks * 0.01
        decide_s = np.asarray(block.decide_ms) / 1e3
        context = {"n": group.n, "graph": group.graph_kind, "duration_s": group.duration, "decisions": len(decide_s)}
        for stat, value in (("p50", np.percentile(decide_s, 50)), ("p99", np.percentile(decide_s, 99))):
            yield {
                "name": f"replan.{label}.decide_{stat}_s",
                "value": float(value),
                "unit": "s",
                "reference": period,
                "ratio": float(value) / period,
            } | context
        top = float(decide_s.max())
        yield {
            "name": f"replan.{label}.decide_max_s",
            "value": top,
            "unit": "s",
            "reference": period,
            "ratio": top / period,
        } | context
        yield {"name": f"replan.{label}.r", "value": r, "unit": "r", "reference": r0, "ratio": r / r0} | context
        seconds = min(live_s, group.duration)
        threaded = RecedingPlanMotion(  # MOTIONS["replan"] on a thread: plans to the (cut) trial's end
            group.n, group.assisted, adjacency=group.graph, end=seconds, horizon=None, compare=None, worker="thread"
        )
        started = time.perf_counter()
        _, tick_p99 = _live(group, threaded, seconds)
        _, mean_p99 = _live(group, MOTIONS["mean"](group), seconds)
        made = len(threaded.decide_ms)
        live = {"n": group.n, "graph": group.graph_kind, "live_s": seconds, "wall_s": time.perf_counter() - started}
        yield {
            "name": f"replan.{label}.live_late",
            "value": threaded.late,
            "unit": "decisions",
            "reference": made,
            "ratio": threaded.late / made if made else None,
        } | live
        yield {
            "name": f"replan.{label}.live_tick_p99_ms",
            "value": tick_p99,
            "unit": "ms",
            "reference": mean_p99,
            "ratio": tick_p99 / mean_p99,
        } | live
