"""What a decision of the default planner ``replan`` (:class:`~cogblocks.sync.receding.RecedingPlanMotion`) costs.

The default planner runs on the largest of the first 20 *validation* groups (N = 15, all-to-all) for ``DURATION``
seconds (``quick``: 20 s), every plan reaching the trial's end, behind the continuous blender; every decision's task
is recorded, then replayed twice in the same process: through the planner as it is, and through the plain
formulations of its rollouts (casadi's interpreter called with casadi matrices, the rule rollouts through the
blender law's generic functions), which decide the same bit for bit (``tests/sync/test_rollouts.py``).

* ``planner.largest.first_s``: CPU seconds of the first decision (the best of the reference rules over the whole
  trial, then the window sweep); reference: the same through the plain formulations, so ``ratio`` is the speed-up's
  inverse.
* ``planner.largest.decide_p50_s`` / ``decide_p99_s``: the later decisions, likewise.
* ``planner.largest.total_s``: all decisions; ``identical`` says whether every replayed plan equals, bit for bit,
  the plain formulations' one.
* ``planner.largest_300s.*``: the same for the first ``LONG_SIMULATED`` seconds (``quick``: 10) of that group's
  trial stretched to 300 s, where every decision plans up to 300 s ahead (the decisions that cost the most).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Iterator

import casadi as ca
import numpy as np

import cogblocks.sync.receding as receding
import cogblocks.sync.rollouts as rollouts
import cogblocks.sync.whole_run as whole_run
from cogblocks.data.groups import random_groups
from cogblocks.diagrams.sync import MOTIONS, pop_sync
from cogblocks.sim import Simulator
from cogblocks.sync.blending import CONTINUOUS, alteration, lam_step
from cogblocks.sync.model import DT

#: Seconds of the trial (``quick``: 20).
DURATION = 60.0
#: Seconds simulated of the 300 s trial (``quick``: 10): its first decisions, each planning to its end.
LONG_SIMULATED = 30.0


def _plain_rollout(roll: ca.Function, x0: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    states, rs, x, chunk = [], [], ca.DM(x0), roll.size2_in(1)
    for start in range(0, len(s), chunk):
        part = s[start : start + chunk]
        xs, r = roll(x, np.pad(part, (0, chunk - len(part)))[None, :])
        xs, r = np.asarray(xs), np.asarray(r).ravel()
        before = np.column_stack([np.asarray(x), xs[:, :-1]])
        states.append(before[:, : len(part)].T)
        rs.append(r[: len(part)])
        x = ca.DM(before[:, len(part)]) if len(part) < chunk else ca.DM(xs[:, -1])
    return np.concatenate(states), np.concatenate(rs)


def _plain_rules(group, adjacency, params, state, rules, n_ticks, record):
    kind, phase0, freq = rules
    b, i, n = len(kind), group.assisted, group.n
    others, omega = np.arange(n) != i, np.asarray(group.omega, dtype=float)
    theta, lam = np.tile(state[:n], (b, 1)), np.full(b, state[n])
    shift = np.full(b, state[-1] if rollouts.memory(params) else 0.0)
    total, s = np.zeros((n_ticks, b) if record else b), (np.zeros((n_ticks, b)) if record else None)
    for k in range(n_ticks):
        z = np.exp(1j * theta)
        reference = np.where(kind == 1, np.angle(z[:, others].sum(axis=1)), phase0 + freq * (k * DT))
        l0 = theta[:, i]
        d = np.where(kind == 0, 0.0, np.mod(reference - l0 + np.pi, 2 * np.pi) - np.pi)
        shift = alteration(d, lam, params, shift, DT)
        z[:, i] = np.exp(1j * (l0 + shift))
        r = np.abs(z.sum(axis=1)) / n
        if record:
            total[k], s[k] = r, shift / lam
        else:
            total += r
        lam = lam_step(lam, shift, params, DT)
        theta = theta + DT * (omega + group.gain * (z.conj() * (z @ adjacency.T)).imag)
    return total, (np.clip(s, -1.0, 1.0) if record else None)


def _plain_stepped(tick: ca.Function, x: np.ndarray, alterations: np.ndarray, n: int) -> np.ndarray:
    for a in alterations:
        x = np.asarray(tick(x, min(max(float(a) / x[n], -1.0), 1.0))[0], dtype=float).ravel()
    return x


def _replay(group, tasks: list, plain: bool) -> tuple[list[float], list]:
    """CPU seconds and results of every decision task, on a fresh block (solvers built before the clock starts)."""
    saved = [
        (m, name, getattr(m, name)) for m in (receding, whole_run) for name in ("alteration_rollout", "rule_rollouts")
    ]
    saved += [(receding, "stepped", receding.stepped), (rollouts, "compiled_rollout", rollouts.compiled_rollout)]
    if plain:
        for module, name, _ in saved[:4]:
            setattr(module, name, _plain_rollout if name == "alteration_rollout" else _plain_rules)
        receding.stepped = _plain_stepped
        rollouts.compiled_rollout = lambda tick, chunk=rollouts.CHUNK: tick.mapaccum("roll", chunk)
    try:
        block = MOTIONS["replan"](group)
        block.plan_through(CONTINUOUS)
        block.worker = "thread"
        block.setup()  # the rollout and the window solver, as a live run builds them before its first tick
        block.worker = "inline"
        seconds, results = [], []
        for task in tasks:
            clock = time.thread_time()
            results.append(block._decide(*task))
            seconds.append(time.thread_time() - clock)
        return seconds, results
    finally:
        for module, name, value in saved:
            setattr(module, name, value)


def _case(label: str, duration: float, simulated: float) -> Iterator[dict]:
    group = max(random_groups(20, "validation", 0), key=lambda g: (g.n, g.graph_kind == "all"))
    group = dataclasses.replace(group, duration=duration)
    tasks = []
    original = receding.RecedingPlanMotion._decide

    def record(block, *task):
        tasks.append(tuple(np.array(v) if isinstance(v, np.ndarray) else v for v in task))
        return original(block, *task)

    receding.RecedingPlanMotion._decide = record
    try:
        Simulator(pop_sync(group, motion=MOTIONS["replan"](group))).run(n_steps=round(simulated / DT) + 1)
    finally:
        receding.RecedingPlanMotion._decide = original
    fast, fast_plans = _replay(group, tasks, plain=False)
    plain, plain_plans = _replay(group, tasks, plain=True)
    identical = all(
        a[2] == b[2] and all(np.array_equal(a[j], b[j]) for j in (0, 1, 3))
        for a, b in zip(fast_plans, plain_plans, strict=True)
    )
    context = {"n": group.n, "graph": group.graph_kind, "duration_s": group.duration, "simulated_s": simulated}
    context |= {"decisions": len(tasks), "identical": identical}
    stats = {
        "first_s": (fast[0], plain[0]),
        "decide_p50_s": (np.percentile(fast[1:], 50), np.percentile(plain[1:], 50)),
        "decide_p99_s": (np.percentile(fast[1:], 99), np.percentile(plain[1:], 99)),
        "total_s": (sum(fast), sum(plain)),
    }
    for stat, (value, reference) in stats.items():
        yield {
            "name": f"planner.{label}.{stat}",
            "value": float(value),
            "unit": "s",
            "reference": float(reference),
            "ratio": float(value) / float(reference),
        } | context


def run(quick: bool = False) -> Iterator[dict]:
    """Yield the decisions' CPU time against the plain formulations', replayed on the same tasks."""
    duration = 20.0 if quick else DURATION
    yield from _case("largest", duration, duration)
    yield from _case("largest_300s", 300.0, 10.0 if quick else LONG_SIMULATED)
