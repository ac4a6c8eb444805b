"""The pacing motion computer (``pace``) on Table 2's groups: its decision latency and the change of r.

* ``pace.latency_p50`` / ``_p99``: CPU time of one decision (simulating every candidate over the horizon)
  in ms, over the decisions of the three runs; reference: the 10 ms tick. A decision is taken every
  ``decide_every`` seconds (1 s) and applies from the next tick, so in a real-time loop it may run beside the
  ticks for a whole period: ``pace.latency_p99_period`` has the period as reference.
* ``pace.per_tick_ms``: the decisions' CPU time spread over the ticks of the runs (amortised cost).
* ``pace.group<N>.change_pct``: change of the time-averaged r relative to no L2; reference: ``mean``'s.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from cogblocks.data.groups import TABLE2
from cogblocks.diagrams.sync import pop_sync
from cogblocks.sim import Simulator
from cogblocks.sync import PacingMotion

BUDGET_MS = 10.0


def mean_r(group, motion, n_steps: int) -> float:
    """Time-averaged r of ``group`` over ``n_steps`` ticks with ``motion`` (None: without L2)."""
    return float(
        Simulator(pop_sync(group, l2=motion is not None, motion=motion or "mean")).run(n_steps=n_steps)["r"].mean()
    )


def change_row(name: str, r: float, r0: float, r_mean: float, duration: float) -> dict:
    """The change of r relative to no L2 (``r0``) in %, with ``mean``'s change as reference."""
    pct, mean_pct = 100.0 * (r - r0) / r0, 100.0 * (r_mean - r0) / r0
    return {
        "name": name,
        "value": pct,
        "unit": "%",
        "reference": mean_pct,
        "ratio": pct / mean_pct,
        "duration_s": duration,
    }


def run(quick: bool = False) -> Iterator[dict]:
    """Yield decision latency and r changes; ``quick`` shortens groups 2 and 3 to 30 s."""
    decide_ms: list[float] = []
    ticks = 0
    for number, group in TABLE2.items():
        duration = min(group.duration, 30.0) if quick else group.duration
        n_steps = round(duration / 0.01) + 1
        r0, r_mean = mean_r(group, None, n_steps), mean_r(group, "mean", n_steps)
        pace = PacingMotion(group.n, group.assisted, adjacency=group.graph)
        r_pace = mean_r(group, pace, n_steps)
        decide_ms += pace.decide_ms
        ticks += n_steps
        yield change_row(f"pace.group{number}.change_pct", r_pace, r0, r_mean, duration)
    for q in (50, 99):
        ms = float(np.percentile(decide_ms, q))
        yield {"name": f"pace.latency_p{q}", "value": ms, "unit": "ms", "reference": BUDGET_MS, "ratio": ms / BUDGET_MS}
    ms, period_ms = float(np.percentile(decide_ms, 99)), PacingMotion(2, 0).decision_period * 1e3
    yield {
        "name": "pace.latency_p99_period",
        "value": ms,
        "unit": "ms",
        "reference": period_ms,
        "ratio": ms / period_ms,
    }
    per_tick = float(np.sum(decide_ms)) / ticks
    yield {
        "name": "pace.per_tick_ms",
        "value": per_tick,
        "unit": "ms",
        "reference": BUDGET_MS,
        "ratio": per_tick / BUDGET_MS,
    }
