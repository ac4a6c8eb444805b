"""Scaling of the group plant: microseconds per tick of a KuramotoGroup on a ring of N participants.

* ``scaling.ring.n<N>.tick_us`` for N = 7, 1 000, 10 000, 100 000 (edge-list coupling from N = 65
  on, chosen automatically); reference: N = 7, so the ratio shows how the cost grows (a ring has
  2N edges: linear growth means ratios near N / 7 once the per-tick overhead is amortised).
* ``scaling.ring.n1000.dense.tick_us``: the dense N × N product forced at N = 1 000; reference:
  the automatic (edge-list) coupling at the same N.
All are measured in the same run, as a one-block diagram through the engine (one output and one
update per tick).
"""

from __future__ import annotations

import time
from collections.abc import Iterator

import numpy as np

from cogblocks.sim import Diagram, Simulator
from cogblocks.sync import KuramotoGroup

SIZES = (7, 1_000, 10_000, 100_000)


def _tick_us(n: int, n_steps: int, sparse: bool | None = None) -> float:
    omega = np.random.default_rng(0).normal(3.0, 0.5, n)
    d = Diagram()
    d.add("group", KuramotoGroup(omega, 1.0, sparse=sparse))
    sim = Simulator(d)
    sim.run(n_steps=2)  # compile and warm up outside the timing
    start = time.perf_counter()
    sim.run(n_steps=n_steps)
    return (time.perf_counter() - start) / n_steps * 1e6


def run(quick: bool = False) -> Iterator[dict]:
    """Yield µs per tick for each ring size, and the dense product at N = 1 000."""
    steps = {7: 3000, 1_000: 1000, 10_000: 200, 100_000: 30}
    if quick:
        steps = {n: max(5, s // 10) for n, s in steps.items()}
    times = {n: _tick_us(n, steps[n]) for n in SIZES}
    for n in SIZES:
        yield {
            "name": f"scaling.ring.n{n}.tick_us",
            "value": times[n],
            "unit": "us/tick",
            "reference": times[7],
            "ratio": times[n] / times[7],
            "edges": 2 * n,
        }
    dense = _tick_us(1_000, steps[1_000] // 5, sparse=False)
    yield {
        "name": "scaling.ring.n1000.dense.tick_us",
        "value": dense,
        "unit": "us/tick",
        "reference": times[1_000],
        "ratio": dense / times[1_000],
        "edges": 2_000,
    }
