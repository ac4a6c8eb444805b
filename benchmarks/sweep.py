"""Sweeps: the speed-up of 2 workers over one, and the per-task overhead of loky and Dask.

* ``sweep.loky.speedup`` / ``sweep.dask.speedup``: wall time of a sweep of short closed-loop runs
  (Kuramoto groups of 7 with seeded frequencies and phases, gain × seed; 120 runs of 30 s simulated
  time) run serially, divided by the same sweep on 2 workers; reference: the goal of 1.7.
* ``sweep.loky.overhead_ms`` / ``sweep.dask.overhead_ms``: the time a worker spends per task
  beyond the run itself (``(2 × wall of 2 workers − serial wall) / tasks``, on tasks of one tick);
  reference: the mean run time of one short run, so the ratio is the overhead's share of a run.

Workers are started and warmed (cogblocks imported) before timing: the times are those of a running
pool, as in a long sweep; the start-up is reported apart (``sweep.<backend>.startup_s``).
"""

from __future__ import annotations

import time
from collections.abc import Iterator

import numpy as np

from cogblocks.blocks import Probe
from cogblocks.experiments.sweep import sweep
from cogblocks.sim import Diagram
from cogblocks.sync import KuramotoGroup, OrderParameter

GOAL_SPEEDUP = 1.7
WORKERS = 2


def build(gain: float, seed: int) -> Diagram:
    """A ring of 7 oscillators, frequencies and initial phases drawn from the seed."""
    rng = np.random.default_rng(seed)
    d = Diagram()
    group = d.add("group", KuramotoGroup(rng.uniform(2.0, 4.0, 7), gain, theta0=rng.uniform(-np.pi, np.pi, 7)))
    order = d.add("order", OrderParameter())
    d.connect(group.theta, order.theta)
    d.add("r", Probe())
    d.connect(order.r, "r.u")
    return d


def measure(trace) -> dict[str, float]:
    return {"r_mean": float(trace["r"].mean())}


def _wall(backend: str, n_runs: int, n_steps: int, client=None) -> float:
    gains = list(np.linspace(0.1, 1.5, 6))
    start = time.perf_counter()
    sweep(
        build,
        {"gain": gains},
        seeds=max(1, n_runs // len(gains)),
        measure=measure,
        n_steps=n_steps,
        backend=backend,
        n_jobs=WORKERS,
        client=client,
        progress=False,
    )
    return time.perf_counter() - start


def run(quick: bool = False) -> Iterator[dict]:
    """Yield the speed-up and overhead of loky and Dask against serial runs."""
    from distributed import Client, LocalCluster

    n_runs, n_steps = (24, 3000) if quick else (120, 3000)
    serial = _wall("serial", n_runs, n_steps)
    serial_trivial = _wall("serial", n_runs, 1)
    per_run = serial / n_runs
    start = time.perf_counter()
    _wall("loky", 2 * WORKERS, 1)  # start and warm the pool
    startups = {"loky": time.perf_counter() - start}
    start = time.perf_counter()
    with (
        LocalCluster(
            n_workers=WORKERS, threads_per_worker=1, host="127.0.0.1", dashboard_address=None, processes=True
        ) as cluster,
        Client(cluster) as client,
    ):
        _wall("dask", 2 * WORKERS, 1, client)
        startups["dask"] = time.perf_counter() - start
        walls = {"dask": (_wall("dask", n_runs, n_steps, client), _wall("dask", n_runs, 1, client))}
    walls["loky"] = (_wall("loky", n_runs, n_steps), _wall("loky", n_runs, 1))
    context = {"runs": n_runs, "ticks_per_run": n_steps, "workers": WORKERS, "serial_s": serial}
    for backend in ("loky", "dask"):
        wall, trivial = walls[backend]
        speedup = serial / wall
        yield {
            "name": f"sweep.{backend}.speedup",
            "value": speedup,
            "unit": "x",
            "reference": GOAL_SPEEDUP,
            "ratio": speedup / GOAL_SPEEDUP,
            **context,
            "wall_s": wall,
        }
        overhead_ms = (WORKERS * trivial - serial_trivial) / n_runs * 1e3
        yield {
            "name": f"sweep.{backend}.overhead_ms",
            "value": overhead_ms,
            "unit": "ms/task",
            "reference": per_run * 1e3,
            "ratio": overhead_ms / (per_run * 1e3),
            **context,
        }
        yield {
            "name": f"sweep.{backend}.startup_s",
            "value": startups[backend],
            "unit": "s",
            "reference": per_run,
            "ratio": startups[backend] / per_run,
        }
