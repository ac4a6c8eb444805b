"""PoP of Social Connectedness: closed-loop speed and the L2 block's per-tick latency.

* ``sync.group3.<policy>.speed``: the 300 s Group 3 closed loop with L2, in
  simulated seconds per wall second; reference: the same loop without L2.
* ``sync.l2.<policy>.latency_p50`` / ``_p99``: one ``step()`` of the L2 block
  alone (compiled on its own, fed the recorded phases of a closed-loop run), in
  milliseconds; reference: the 10 ms real-time budget.
"""

from __future__ import annotations

import time
from collections.abc import Iterator

import numpy as np

from cogblocks.data.groups import TABLE2
from cogblocks.diagrams.sync import MOTIONS, pop_sync
from cogblocks.sim import Simulator
from cogblocks.sync import L2Sync

BUDGET_MS = 10.0


def _speed(diagram, n_steps: int) -> float:
    sim = Simulator(diagram)
    start = time.perf_counter()
    sim.run(n_steps=n_steps)
    return (n_steps - 1) * sim.dt / (time.perf_counter() - start)


def run(quick: bool = False) -> Iterator[dict]:
    """Yield the closed-loop speed and L2 latency for every motion computer."""
    group = TABLE2[3]
    n_steps = 3001 if quick else 30001
    baseline = _speed(pop_sync(group, l2=False), n_steps)
    for policy in MOTIONS:
        speed = _speed(pop_sync(group, l2=True, motion=policy), n_steps)
        yield {
            "name": f"sync.group3.{policy}.speed",
            "value": speed,
            "unit": "sim_s/wall_s",
            "reference": baseline,
            "ratio": speed / baseline,
        }
    phases = Simulator(pop_sync(group, l2=False), probes=["group.theta"]).run(n_steps=n_steps)["group.theta"]
    for policy in MOTIONS:
        l2 = L2Sync(MOTIONS[policy](group), group.assisted).compile()
        times = np.empty(len(phases))
        for k, theta in enumerate(phases):
            start = time.perf_counter()
            l2.step(theta=theta)
            times[k] = time.perf_counter() - start
        for q in (50, 99):
            ms = float(np.percentile(times, q) * 1e3)
            yield {
                "name": f"sync.l2.{policy}.latency_p{q}",
                "value": ms,
                "unit": "ms",
                "reference": BUDGET_MS,
                "ratio": ms / BUDGET_MS,
            }
