"""Many runs in one compiled diagram: the Table 2 group 3 closed loop on a batch of B runs.

* ``batch.group3.mean.vs_numpy``: µs per simulated group-tick of the closed loop with the L2 block, the
  circular-mean motion computer and the default (continuous) blender, compiled with ``batch=B``
  (B = 1000, r recorded every tick); reference: a hand-written batched NumPy loop of the same closed
  loop, written here. Goal: ratio <= 2.
* ``batch.group3.mean.vs_one_run``: the same batched cost per group-tick; reference: the per-tick cost
  of one unbatched run of the diagram. Goal: ratio <= 1/20.
* ``batch.group3.dqn_raw.vs_one_run``: the same with the trained DQN motion computer (``dqn_raw``).
  Goal: ratio <= 1/10. Torch runs on one thread here, in the batch and in the single run alike: on a
  machine whose cores are busy, its worker threads wait on each other far longer than the forward
  pass takes (a ReLU of 1000 x 128 values: 17 ms on two threads, 32 µs on one, measured here).

Each line also carries ``max_r_difference``: the largest difference of r between the batched diagram and
the NumPy loop (or one run), which says the two compute the same thing.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Iterator

import numpy as np

from cogblocks.data.groups import TABLE2
from cogblocks.diagrams.sync import pop_sync
from cogblocks.sim import Simulator
from cogblocks.sync.blending import CONTINUOUS

TWO_PI = 2.0 * math.pi


def _numpy_loop(group, batch: int, n_steps: int, dt: float = 0.01) -> np.ndarray:
    """The closed loop (plant, circular-mean reference, continuous blender, r) as plain batched NumPy; r per tick."""
    p = CONTINUOUS
    n, a = group.n, group.assisted
    adjacency = np.asarray(group.adjacency(), dtype=float)
    omega = np.asarray(group.omega, dtype=float)
    others = np.array([j for j in range(n) if j != a])
    phase = np.zeros((batch, n))
    lam = np.full(batch, p.lam_max)
    prev = np.zeros(batch)
    ref = np.zeros(batch)
    seen = np.empty((batch, n))
    r = np.empty((n_steps, batch))
    step = p.slew * dt
    span = p.lam_max - p.lam_min
    for k in range(n_steps):
        l0 = phase[:, a]
        c = np.cos(phase[:, others]).sum(axis=1)
        s = np.sin(phase[:, others]).sum(axis=1)
        ref = np.where((c != 0) | (s != 0), np.mod(np.arctan2(s, c), TWO_PI), ref)
        d = np.pi - np.mod(np.pi - (ref - l0), TWO_PI)
        d = prev + (np.pi - np.mod(np.pi - (d - prev), TWO_PI))
        shift = np.clip(np.clip(np.clip(d, -lam, lam), prev - step, prev + step), -lam, lam)
        l2 = np.mod(l0 + shift, TWO_PI)
        seen[...] = phase
        seen[:, a] = l2
        r[k] = np.hypot(np.cos(seen).sum(axis=1), np.sin(seen).sum(axis=1)) / n
        e = np.pi - np.mod(np.pi - (l2 - l0), TWO_PI)
        target = np.maximum(0.0, 1.0 - np.abs(e / p.e_max)) * span + p.lam_min
        lam = lam - dt * np.where(lam <= target, p.kappa_plus, p.kappa_minus) * (lam - target)
        prev = shift
        pull = (adjacency * np.sin(seen[:, None, :] - seen[:, :, None])).sum(axis=2)
        phase = np.mod(phase + dt * (omega + group.gain * pull), TWO_PI)
    return r


def _timed(f):
    start = time.perf_counter()
    out = f()
    return time.perf_counter() - start, out


def _diagram_batch(group, motion: str, batch: int, n_steps: int) -> tuple[float, np.ndarray, tuple]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a per-row block is reported below, in the result's context
        sim = Simulator(pop_sync(group, motion=motion), batch=batch, progress=False)
    seconds, trace = _timed(lambda: sim.run(n_steps=n_steps))
    return seconds, trace["r"], sim.compiled.per_row


def _one_run(group, motion: str, n_steps: int) -> tuple[float, np.ndarray]:
    sim = Simulator(pop_sync(group, motion=motion), progress=False)
    seconds, trace = _timed(lambda: sim.run(n_steps=n_steps))
    return seconds, trace["r"]


def _best(f, repeats: int):
    """The fastest of ``repeats`` calls (a shared machine only ever slows a run down)."""
    results = [f() for _ in range(repeats)]
    return min(results, key=lambda x: x[0])


def run(quick: bool = False) -> Iterator[dict]:
    """Yield the batched closed loop's cost per group-tick against a NumPy loop and against one run."""
    group = TABLE2[3]
    batch = 100 if quick else 1000
    n_steps = 50 if quick else 300
    repeats = 1 if quick else 5
    us = 1e6 / (batch * n_steps)

    diagram_s, r_diagram, per_row = _best(lambda: _diagram_batch(group, "mean", batch, n_steps), repeats)
    numpy_s, r_numpy = _best(lambda: _timed(lambda: _numpy_loop(group, batch, n_steps)), repeats)
    one_steps = n_steps * (2 if quick else 10)
    one_s, r_one = _best(lambda: _one_run(group, "mean", one_steps), repeats)
    context = {"batch": batch, "ticks": n_steps, "per_row": list(per_row)}
    yield {
        "name": "batch.group3.mean.vs_numpy",
        "value": diagram_s * us,
        "unit": "us/group-tick",
        "reference": numpy_s * us,
        "ratio": diagram_s / numpy_s,
        "max_r_difference": float(np.max(np.abs(r_diagram - r_numpy))),
        **context,
    }
    one_us = one_s * 1e6 / one_steps
    yield {
        "name": "batch.group3.mean.vs_one_run",
        "value": diagram_s * us,
        "unit": "us/group-tick",
        "reference": one_us,
        "ratio": diagram_s * us / one_us,
        "max_r_difference": float(np.max(np.abs(r_diagram[:, 0] - r_one[:n_steps]))),
        **context,
    }
    dqn_batch = batch
    dqn_steps = n_steps // 2
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        dqn_s, r_dqn, dqn_rows = _best(lambda: _diagram_batch(group, "dqn_raw", dqn_batch, dqn_steps), repeats)
        one_dqn_s, r_one_dqn = _best(lambda: _one_run(group, "dqn_raw", dqn_steps * 4), repeats)
    finally:
        torch.set_num_threads(threads)
    dqn_us = dqn_s * 1e6 / (dqn_batch * dqn_steps)
    one_dqn_us = one_dqn_s * 1e6 / (dqn_steps * 4)
    yield {
        "name": "batch.group3.dqn_raw.vs_one_run",
        "value": dqn_us,
        "unit": "us/group-tick",
        "reference": one_dqn_us,
        "ratio": dqn_us / one_dqn_us,
        "max_r_difference": float(np.max(np.abs(r_dqn[:, 0] - r_one_dqn[:dqn_steps]))),
        "batch": dqn_batch,
        "ticks": dqn_steps,
        "per_row": list(dqn_rows),
    }
