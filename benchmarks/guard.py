"""The guarded pacing motion computer (``guard``) on Table 2's groups: its CPU time per tick and the change of r.

* ``guard.tick_p50`` / ``_p99`` / ``_max``: CPU time (ms) of the block's update on one tick, over every tick
  of the three runs; reference: the 10 ms tick. A decision is spread over the ticks of its period (a few
  Euler steps each), so this is the latency a live loop sees, not an amortised figure.
* ``guard.per_tick_ms``: the mean of the above (amortised cost).
* ``guard.group<N>.change_pct``: change of the time-averaged r relative to no L2; reference: ``mean``'s.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from dataclasses import replace

import numpy as np

from benchmarks.pace import change_row, mean_r
from cogblocks.data.groups import TABLE2
from cogblocks.sync.guarded import GuardedPacingMotion

BUDGET_MS = 10.0


def _timed(block: GuardedPacingMotion, record: list[float]) -> GuardedPacingMotion:
    """``block`` with the CPU time of every update appended to ``record`` (ms)."""
    update = block.update

    def timed(k: int) -> None:
        start = time.thread_time()
        update(k)
        record.append((time.thread_time() - start) * 1e3)

    block.update = timed
    return block


def run(quick: bool = False) -> Iterator[dict]:
    """Yield per-tick CPU time and r changes; ``quick`` shortens groups 2 and 3 to 30 s."""
    tick_ms: list[float] = []
    for number, group in TABLE2.items():
        duration = min(group.duration, 30.0) if quick else group.duration
        n_steps = round(duration / 0.01) + 1
        r0, r_mean = mean_r(group, None, n_steps), mean_r(group, "mean", n_steps)
        # as the retired name ``guard`` builds it for this run: predictions stop at the run's end
        trial = replace(group, duration=duration)
        guard = GuardedPacingMotion.for_trial(trial.n, trial.assisted, adjacency=trial.graph, end=trial.duration)
        block = _timed(guard, tick_ms)
        r_guard = mean_r(group, block, n_steps)
        yield change_row(f"guard.group{number}.change_pct", r_guard, r0, r_mean, duration)
    for label, ms in (
        ("tick_p50", np.percentile(tick_ms, 50)),
        ("tick_p99", np.percentile(tick_ms, 99)),
        ("tick_max", np.max(tick_ms)),
        ("per_tick_ms", np.mean(tick_ms)),
    ):
        ms = float(ms)
        yield {"name": f"guard.{label}", "value": ms, "unit": "ms", "reference": BUDGET_MS, "ratio": ms / BUDGET_MS}
