"""Per-tick latency of the online 3D phase estimator, warm-started search against full search.

    python benchmarks/phase3d_latency.py [--quick]

A :class:`PhaseEstimator3D` is compiled alone and fed one position per ``compiled.step(p=...)``
call, as in a live loop. Each call is timed with ``time.thread_time_ns``, the CPU time of the
calling thread: on a shared machine the wall-clock time also counts the slices the scheduler gives
other processes, which swamp the 99th percentile (milliseconds instead of tens of microseconds).
The figures include the engine's per-tick overhead and every block of the estimator (the period
estimator, the customiser when a period completes, the phase computer); garbage collection is off
while timing. The phase computer searches the
customised reference, which has as many samples as the reference (its phase grid), and the
trajectories are sampled with ``N`` samples per nominal cycle (clean: no noise, no drop-outs), for
``N`` = 200, 2000, 20000; the estimator's rules in seconds (``h``, ``window``,
``velocity_weight``) are set to 10, 10 and 1 samples, the deliverable's values at 100 Hz. Only the
ticks after the first period count (before it there is nothing to search). Prints one JSON object
per line, the warm search's percentile with the full search's as reference;
``ratio = value / reference``.

The tick on which a period completes also fits the reference to it (:func:`anchored_reference`).
Its cost is timed on 30 s of the harder set (``MOTION3D_SETS["harder"]``, first trajectory of
``SeedSequence(0)``) at 100 and 240 Hz, with the estimator's defaults: the first period's fitting
tick, the median of the later ones (``reference``: the median of the other ticks) and the
percentiles of the other ticks after the first period.
"""

from __future__ import annotations

import argparse
import gc
import json
import sys
import time
from collections.abc import Iterator

import numpy as np

from cogblocks.data.motion3d import generate_motion3d
from cogblocks.diagrams.phase3d import MOTION3D_SETS
from cogblocks.phase import PhaseEstimator3D

SIZES = (200, 2000, 20000)
PERIOD_S = 2.0


def _tick_latencies(n_reference: int, search: str, n_measured: int) -> np.ndarray:
    """Microseconds per ``compiled.step`` call over ``n_measured`` ticks after the first period."""
    dt = PERIOD_S / n_reference
    duration = (1.4 * n_reference + n_measured) * dt  # the first period (with its drift) and the measured ticks
    motion = generate_motion3d(
        0,
        duration=duration,
        dt=dt,
        period=PERIOD_S,
        period_spread=0.0,
        noise_mm=0.0,
        dropout_rate=0.0,
        n_reference=n_reference,
    )
    # the rules are in seconds; at N samples per cycle the deliverable's 10 samples are 10 dt
    estimator = PhaseEstimator3D(
        motion.reference, capacity=2 * n_reference, search=search, h=10 * dt, window=10 * dt, velocity_weight=dt
    )
    compiled = estimator.compile(dt)
    positions = motion.position
    k = 0
    while not compiled.step(p=positions[k])["valid"]:
        k += 1
    if k + n_measured > len(positions):
        raise RuntimeError(f"the first period ended at tick {k}, too late to measure {n_measured} ticks")
    times = np.empty(n_measured)
    clock = time.thread_time_ns
    step = compiled.step
    gc.disable()  # a collection in the middle of a tick is not the estimator's cost
    try:
        for i in range(n_measured):
            p = positions[k + i]
            start = clock()
            step(p=p)
            times[i] = clock() - start
    finally:
        gc.enable()
    return times / 1e3


def _fit_tick_latencies(rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Microseconds of each tick of 30 s of the harder set after the first period, and whether it fitted a period."""
    child = np.random.SeedSequence(0).spawn(1)[0]
    motion = generate_motion3d(np.random.default_rng(child), duration=30.0, dt=1.0 / rate_hz, **MOTION3D_SETS["harder"])
    estimator = PhaseEstimator3D(motion.reference)
    compiled = estimator.compile(motion.dt)
    count = estimator.blocks["customizer"].count  # the customised reference's period counter: changes on a fit
    times, fitted = np.empty(len(motion.t)), np.zeros(len(motion.t), dtype=bool)
    clock = time.thread_time_ns
    gc.disable()
    try:
        for i, p in enumerate(motion.position):
            before = int(count.value)
            start = clock()
            compiled.step(p=p)
            times[i] = clock() - start
            fitted[i] = int(count.value) != before
    finally:
        gc.enable()
    first = int(np.argmax(fitted))
    return times[first:] / 1e3, fitted[first:]


def run_fit_ticks() -> Iterator[dict]:
    """The period-completing ticks' cost against the other ticks', at 100 and 240 Hz."""
    for rate in (100, 240):
        times, fitted = _fit_tick_latencies(rate)
        other = times[~fitted]
        normal = float(np.median(other))
        figures = {
            "first_fit": float(times[0]),
            "fit.p50": float(np.median(times[1:][fitted[1:]])),
            "fit.max": float(times[1:][fitted[1:]].max()),
            "other.p99": float(np.percentile(other, 99)),
        }
        yield {
            "name": f"phase3d.latency.{rate}hz.other.p50",
            "value": normal,
            "unit": "us",
            "reference": normal,
            "ratio": 1.0,
        }
        for stat, value in figures.items():
            yield {
                "name": f"phase3d.latency.{rate}hz.{stat}",
                "value": value,
                "unit": "us",
                "reference": normal,
                "ratio": value / normal,
                "n_fits": int(fitted.sum()),
            }


def run(quick: bool = False) -> Iterator[dict]:
    """Time the warm and the full search for each reference size; yield the warm figures; then the fitting ticks."""
    yield from run_fit_ticks()
    n_measured = 300 if quick else 3000
    for n in SIZES:
        warm = _tick_latencies(n, "warm", n_measured)
        full = _tick_latencies(n, "full", n_measured)
        for stat, q in (("p50", 50), ("p99", 99)):
            value, reference = float(np.percentile(warm, q)), float(np.percentile(full, q))
            yield {
                "name": f"phase3d.latency.warm.{n}.{stat}",
                "value": value,
                "unit": "us",
                "reference": reference,
                "ratio": value / reference,
                "n_ticks": n_measured,
            }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="fewer timed ticks, for a smoke test")
    args = parser.parse_args(argv)
    for result in run(quick=args.quick):
        print(json.dumps(result), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
