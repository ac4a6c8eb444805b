"""Soak test: 24 simulated hours of the Group 3 closed loop, one hour per ``run()`` call.

``pop_sync(3, motion="mean")`` (8.64 million ticks of 10 ms) is run by one
:class:`~cogblocks.sim.Simulator` with decimated probes (every 100th tick of ``r``
and ``group.theta``), in successive ``run()`` calls of one simulated hour each;
each hour's trace is dropped before the next hour starts, as a long-running
logger would write it away. At 1, 6 and 24 simulated hours it reports:

* ``soak.sync3.wall.<t>``: wall seconds of the hour that ends at ``t``;
  reference: the first hour (a ratio above 1 is a slowdown over time);
* ``soak.sync3.cpu.<t>``: CPU seconds of the process in that hour, which a
  busy shared machine disturbs less than the wall time; reference: the first hour;
* ``soak.sync3.elapsed.<t>``: wall seconds since the start; reference: the
  first hour times the number of hours;
* ``soak.sync3.peak_mem.<t>``: tracemalloc peak of that hour in MiB (what the
  Python allocator held at most since the diagram was built: the diagram, the
  hour's trace and whatever earlier hours left behind);
  reference: the first hour. Memory must not grow with run length: ratio ~1;
* ``soak.sync3.retained.<t>``: traced memory still held at the end of the hour,
  MiB; reference: the same after the first hour;
* ``soak.sync3.maxrss.<t>``: the process's peak resident set (``getrusage``),
  MiB, which also sees memory outside the Python allocator (NumPy buffers
  allocated by C code, torch); reference: after the first hour.

tracemalloc is on for the whole soak, so the wall times include its overhead
(about 2.5 times slower than without it); they are meant to be compared with
each other, not with ``benchmarks/sync.py``. ``quick=True`` simulates hours of
6 minutes (checkpoints at 0.1, 0.6 and 2.4 simulated hours).

    python benchmarks/soak.py [--quick]
"""

from __future__ import annotations

import gc
import json
import resource
import sys
import time
import tracemalloc
from collections.abc import Iterator
from pathlib import Path

HOURS = 24
CHECKPOINTS = (1, 6, 24)
DECIMATE = 100
_MIB = 1024.0 * 1024.0


def _maxrss_mib() -> float:
    # ru_maxrss is in KiB on Linux (bytes on macOS)
    scale = 1.0 if sys.platform == "darwin" else 1024.0
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * scale / _MIB


def run(quick: bool = False) -> Iterator[dict]:
    """Simulate 24 'hours' (of 1 h, or 6 min with ``quick``) and yield figures at hours 1, 6 and 24."""
    from cogblocks.diagrams.sync import pop_sync
    from cogblocks.sim import Simulator

    hour = 360.0 if quick else 3600.0  # simulated seconds per run() call
    was_tracing = tracemalloc.is_tracing()
    if not was_tracing:
        tracemalloc.start()  # before the diagram is built, so that its own memory is counted too
    sim = Simulator(pop_sync(3, motion="mean"), decimate=DECIMATE, probes=["group.theta"], progress=False)
    n_steps = sim.steps(hour)
    first: dict[str, float] = {}
    elapsed = 0.0
    try:
        for h in range(1, HOURS + 1):
            gc.collect()
            tracemalloc.reset_peak()
            start, cpu_start = time.perf_counter(), time.process_time()
            trace = sim.run(n_steps=n_steps)
            wall, cpu = time.perf_counter() - start, time.process_time() - cpu_start
            elapsed += wall
            r_last = float(trace["r"][-1])
            del trace  # a logger would have written the hour away
            gc.collect()
            retained, peak = (x / _MIB for x in tracemalloc.get_traced_memory())
            figures = {
                "wall": wall,
                "cpu": cpu,
                "elapsed": elapsed,
                "peak_mem": peak,
                "retained": retained,
                "maxrss": _maxrss_mib(),
            }
            if h == 1:
                first = dict(figures)
            if h not in CHECKPOINTS:
                continue
            simulated_h = h * hour / 3600.0
            label = f"{h}h" if not quick else f"{h * hour / 60.0:g}min"
            references = dict(first, elapsed=first["wall"] * h)
            units = {"wall": "s", "cpu": "s", "elapsed": "s", "peak_mem": "MiB", "retained": "MiB", "maxrss": "MiB"}
            for metric, value in figures.items():
                ref = references[metric]
                yield {
                    "name": f"soak.sync3.{metric}.{label}",
                    "value": value,
                    "unit": units[metric],
                    "reference": ref,
                    "ratio": value / ref if ref else float("nan"),
                    "simulated_hours": simulated_h,
                    "ticks": h * n_steps,
                    "r_last": r_last,
                }
    finally:
        if not was_tracing:
            tracemalloc.stop()


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
    for result in run(quick="--quick" in sys.argv[1:]):
        print(json.dumps(result), flush=True)
