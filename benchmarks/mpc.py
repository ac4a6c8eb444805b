"""The model-predictive motion computer against the baselines and the per-group bound (Table 2's groups).

* ``mpc.tick_ms_p50`` / ``_p99`` / ``_max``: CPU time (ms) of one tick that works on a decision (the
  screening on the decision's tick, one IPOPT chunk on each following tick until the solve ends), over the
  three MPC runs (identified model); reference: the 10 ms tick budget.
* ``mpc.latency_p50`` / ``_p99``: CPU time of one whole decision (its ticks summed) in ms; reference: the
  10 ms tick. A decision is taken every ``decide_every`` seconds (0.5 s) and its plan takes effect one
  period later, so the budget it must fit is the period: ``mpc.latency_p99_period`` has the period as
  reference.
* ``mpc.group<N>.<policy>.change_pct``: change of the time-averaged r relative to no L2, for ``mean``,
  ``lookahead``, ``mpc`` (identified model) and ``mpc_true`` (true model); reference: the change that
  :func:`~cogblocks.evaluation.sync_bound.upper_bound` reaches, so ``ratio`` is the fraction of the bound's gain.
* ``mpc.group<N>.<policy>.bound_fraction``: r / bound.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from cogblocks.data.groups import TABLE2
from cogblocks.diagrams.sync import pop_sync
from cogblocks.evaluation.sync_bound import upper_bound
from cogblocks.sim import Simulator
from cogblocks.sync import MPCMotion

BUDGET_MS = 10.0


def run(quick: bool = False) -> Iterator[dict]:
    """Yield decision latency and r changes; ``quick`` shortens groups 2 and 3 to 30 s."""
    solve_ms: list[float] = []
    tick_ms: list[float] = []
    for number, group in TABLE2.items():
        duration = min(group.duration, 30.0) if quick else group.duration
        n_steps = round(duration / 0.01) + 1
        r0 = float(Simulator(pop_sync(group, l2=False)).run(n_steps=n_steps)["r"].mean())
        bound = upper_bound(group, duration=duration)
        motions = {
            "mean": "mean",
            "lookahead": "lookahead",
            "mpc": MPCMotion(group.n, group.assisted),
            "mpc_true": MPCMotion(group.n, group.assisted, omega=group.omega, gain=group.gain),
        }
        bound_pct = 100.0 * (bound - r0) / r0
        yield {"name": f"mpc.group{number}.bound", "value": bound, "unit": "r", "reference": r0, "ratio": bound / r0}
        for name, motion in motions.items():
            r = float(Simulator(pop_sync(group, motion=motion)).run(n_steps=n_steps)["r"].mean())
            pct = 100.0 * (r - r0) / r0
            yield {
                "name": f"mpc.group{number}.{name}.change_pct",
                "value": pct,
                "unit": "%",
                "reference": bound_pct,
                "ratio": pct / bound_pct,
                "duration_s": duration,
            }
            yield {
                "name": f"mpc.group{number}.{name}.bound_fraction",
                "value": r / bound,
                "unit": "1",
                "reference": 1.0,
                "ratio": r / bound,
            }
            if name == "mpc":
                solve_ms += motion.solve_ms
                tick_ms += motion.tick_ms
                yield {
                    "name": f"mpc.group{number}.fallbacks",
                    "value": motion.fallbacks,
                    "unit": "decisions",
                    "reference": len(motion.solve_ms),
                    "ratio": motion.fallbacks / len(motion.solve_ms),
                }
    for q, label in ((50, "p50"), (99, "p99"), (100, "max")):
        ms = float(np.percentile(tick_ms, q))
        yield {
            "name": f"mpc.tick_ms_{label}",
            "value": ms,
            "unit": "ms",
            "reference": BUDGET_MS,
            "ratio": ms / BUDGET_MS,
        }
    for q in (50, 99):
        ms = float(np.percentile(solve_ms, q))
        yield {"name": f"mpc.latency_p{q}", "value": ms, "unit": "ms", "reference": BUDGET_MS, "ratio": ms / BUDGET_MS}
    ms, period_ms = float(np.percentile(solve_ms, 99)), MPCMotion(2, 0).decision_period * 1e3
    yield {"name": "mpc.latency_p99_period", "value": ms, "unit": "ms", "reference": period_ms, "ratio": ms / period_ms}
