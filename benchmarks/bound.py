"""The cost of the whole-run upper bound that every sync policy is judged against.

* ``bound.<group>.cpu_s``: CPU seconds of :func:`~cogblocks.evaluation.sync_bound.upper_bound` as the held-out
  evaluation calls it (``pace=False``: the windowed optimal control and the constant-frequency scan);
  reference: the CPU seconds of one closed-loop simulation of the same group without L2, measured in the
  same run, so ``ratio`` is the bound's cost in plain simulations.
* ``bound.<group>.r``: the bound's r; reference: r without L2 (context for the cost).

Groups: Table 2's group 1 (10 s) and the first three groups of the *validation* split (never the test
split); ``quick`` cuts every group to at most 20 s.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Iterator

from cogblocks.data.groups import TABLE2, SyncGroup, random_groups
from cogblocks.diagrams.sync import pop_sync
from cogblocks.evaluation.sync_bound import upper_bound
from cogblocks.sim import Simulator


def plain_runs(quick: bool) -> Iterator[tuple[str, SyncGroup, int, float, float]]:
    """The benchmark's groups: ``(label, group, n_steps, r without L2, CPU seconds of that plain simulation)``."""
    groups = {"group1": TABLE2[1]} | {f"validation{i}": g for i, g in enumerate(random_groups(3, "validation", 0))}
    for label, group in groups.items():
        if quick:
            group = dataclasses.replace(group, duration=min(group.duration, 20.0))
        n_steps = round(group.duration / 0.01) + 1
        start = time.process_time()
        r0 = float(Simulator(pop_sync(group, l2=False)).run(n_steps=n_steps)["r"].mean())
        yield label, group, n_steps, r0, time.process_time() - start


def run(quick: bool = False) -> Iterator[dict]:
    """Yield the bound's CPU time per group against a plain simulation of that group."""
    for label, group, _, r0, sim_s in plain_runs(quick):
        start = time.process_time()
        bound = upper_bound(group, pace=False)
        bound_s = time.process_time() - start
        context = {"n": group.n, "graph": group.graph_kind, "duration_s": group.duration}
        yield {
            "name": f"bound.{label}.cpu_s",
            "value": bound_s,
            "unit": "s",
            "reference": sim_s,
            "ratio": bound_s / sim_s,
        } | context
        yield {"name": f"bound.{label}.r", "value": bound, "unit": "r", "reference": r0, "ratio": bound / r0} | context
