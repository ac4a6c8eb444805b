"""PoP of Amplification benchmark: the library search of the online projector, per decision.

Every ΔT = 10 samples the projector compares the buffered prefix of the human movement with every
library movement. The incremental projector (:class:`~cogblocks.amplification.projector.PrefixProjection`,
what :class:`~cogblocks.amplification.LibraryProjector` runs in its update) only adds the 10 new
samples to running sums; the reference, measured in the same run, re-projects the whole prefix at
every decision. Libraries: the generated one (458 movements) and synthetic ones of 10 000 and
100 000 movements made by drawing movements of it with replacement and jittering them (amplitude
±5 % per axis, 2 mm/s noise). Each decision is timed for several held-out movements; p50 and p99 are
over all decisions. Peak memory (tracemalloc: NumPy's allocations) covers building the search
structure and one movement's decisions.
"""

from __future__ import annotations

import time
import tracemalloc
from collections.abc import Callable, Iterator

import numpy as np

from cogblocks.amplification.projector import PrefixProjection
from cogblocks.data.reach import generate_reach_library

INTERVAL = 10


def synthetic_library(base_velocity: np.ndarray, base_fear: np.ndarray, n: int, seed: int = 0):
    """``n`` movements drawn from a library with replacement and jittered, as float32 ``(n, T, 3)``."""
    rng = np.random.default_rng(seed)
    pick = rng.integers(len(base_velocity), size=n)
    velocity = np.empty((n, base_velocity.shape[1], 3), dtype=np.float32)
    for start in range(0, n, 10_000):  # in slices, so that no float64 copy of the whole library exists
        rows = pick[start : start + 10_000]
        gain = rng.normal(1.0, 0.05, (len(rows), 1, 3))
        moving = base_velocity[rows] != 0
        noise = rng.normal(0.0, 2.0, (len(rows),) + base_velocity.shape[1:]) * moving
        velocity[start : start + len(rows)] = base_velocity[rows] * gain + noise
    return velocity, base_fear[pick]


def incremental_decisions(projection: PrefixProjection, fear: np.ndarray, human: np.ndarray) -> list[float]:
    """Seconds per decision of the incremental search over one movement."""
    no_fear_set, fear_set = np.flatnonzero(~fear), np.flatnonzero(fear)
    sums = np.zeros(projection.size)
    times, reference = [], -1
    for count in range(INTERVAL, len(human) + 1, INTERVAL):
        start = time.perf_counter()
        projection.accumulate(sums, human[count - INTERVAL : count], count - INTERVAL)
        nearest = no_fear_set[np.argmin(sums[no_fear_set])]
        if reference < 0:
            reference = fear_set[np.argmin(sums[fear_set])]
        times.append(time.perf_counter() - start)
    assert nearest >= 0
    return times


def naive_decisions(velocity: np.ndarray, fear: np.ndarray, human: np.ndarray) -> list[float]:
    """Seconds per decision of a full re-projection of the prefix (mean Euclidean distance)."""
    no_fear_set, fear_set = np.flatnonzero(~fear), np.flatnonzero(fear)
    times, reference = [], -1
    for count in range(INTERVAL, len(human) + 1, INTERVAL):
        start = time.perf_counter()
        distance = np.linalg.norm(velocity[:, :count] - human[None, :count].astype(velocity.dtype), axis=2).mean(axis=1)
        nearest = no_fear_set[np.argmin(distance[no_fear_set])]
        if reference < 0:
            reference = fear_set[np.argmin(distance[fear_set])]
        times.append(time.perf_counter() - start)
    assert nearest >= 0
    return times


def _peak_mb(fn: Callable[[], object]) -> float:
    tracemalloc.start()
    try:
        fn()
        return tracemalloc.get_traced_memory()[1] / 2**20
    finally:
        tracemalloc.stop()


def _measure(
    size: int, velocity: np.ndarray, fear: np.ndarray, humans: np.ndarray, dtypes: tuple[str, ...]
) -> Iterator[dict]:
    slow = [t for h in humans for t in naive_decisions(velocity, fear, h)]
    naive_memory = _peak_mb(lambda: naive_decisions(velocity, fear, humans[0]))
    for dtype in dtypes:
        projection = PrefixProjection(velocity, dtype=dtype, block=INTERVAL)
        fast = [t for h in humans for t in incremental_decisions(projection, fear, h)]
        del projection
        label = f"amplification.search.{size}" + ("" if dtype == "float32" else f".{dtype}")
        for q in (50, 99):
            value, reference = np.percentile(fast, q) * 1e3, np.percentile(slow, q) * 1e3
            yield {
                "name": f"{label}.p{q}",
                "value": value,
                "unit": "ms",
                "reference": reference,
                "ratio": value / reference,
                "library": size,
                "decisions": len(fast),
                "dtype": dtype,
            }
        memory = _peak_mb(lambda d=dtype: incremental_decisions(PrefixProjection(velocity, dtype=d), fear, humans[0]))
        yield {
            "name": f"{label}.peak_memory",
            "value": memory,
            "unit": "MiB",
            "reference": naive_memory,
            "ratio": memory / naive_memory,
            "library": size,
            "library_mib": velocity.nbytes / 2**20,
            "dtype": dtype,
        }


def run(quick: bool = False) -> Iterator[dict]:
    """Yield p50/p99 latency per decision and peak memory for each library size.

    The naive reference runs on the same float32 library; the 100 000-movement library is also
    measured with a float64 projector (full run only).
    """
    base = generate_reach_library(0)
    humans = generate_reach_library(1, n_subjects=2, n_fear=0, n_no_fear=6).velocity
    yield from _measure(
        len(base), base.velocity.astype(np.float32), base.fear, humans[: 2 if quick else 6], ("float32",)
    )
    yield from _measure(
        10_000, *synthetic_library(base.velocity, base.fear, 10_000), humans[: 2 if quick else 6], ("float32",)
    )
    if not quick:
        yield from _measure(
            100_000, *synthetic_library(base.velocity, base.fear, 100_000), humans[:3], ("float32", "float64")
        )
