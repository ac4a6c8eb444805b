"""The cost of the planning motion computer ``plan`` (the planner with one decision, ``whole_trial_plan``).

* ``plan.<group>.plan_cpu_s``: CPU seconds of the one tick that plans the rest of the trial (``decide_ms[0]``);
  reference: the CPU seconds of one closed-loop simulation of the same group without L2, measured in the same run,
  so ``ratio`` is the plan's cost in plain simulations. ``per_simulated_s`` is the plan's CPU per second of trial.
* ``plan.<group>.r``: r with ``plan``; reference: r without L2.

Groups: those of :mod:`benchmarks.bound` (Table 2's group 1 and the first three of the *validation* split; ``quick``
cuts every group to at most 20 s).
"""

from __future__ import annotations

from collections.abc import Iterator

from benchmarks.bound import plain_runs
from cogblocks.diagrams.sync import MOTIONS, pop_sync
from cogblocks.sim import Simulator


def run(quick: bool = False) -> Iterator[dict]:
    """Yield the plan's CPU time per group against a plain simulation of that group, and its r."""
    for label, group, n_steps, r0, sim_s in plain_runs(quick):
        block = MOTIONS["plan"](group)
        r = float(Simulator(pop_sync(group, motion=block)).run(n_steps=n_steps)["r"].mean())
        plan_s = (block.decide_ms[0] if block.decide_ms else 0.0) / 1e3  # its one decision
        context = {"n": group.n, "graph": group.graph_kind, "duration_s": group.duration}
        yield {
            "name": f"plan.{label}.plan_cpu_s",
            "value": plan_s,
            "unit": "s",
            "reference": sim_s,
            "ratio": plan_s / sim_s,
            "per_simulated_s": plan_s / group.duration,
        } | context
        yield {"name": f"plan.{label}.r", "value": r, "unit": "r", "reference": r0, "ratio": r / r0} | context
