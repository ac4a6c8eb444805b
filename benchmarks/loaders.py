"""Loader benchmark: :func:`load_csv` time per movement as the library grows.

* ``loaders.csv.<n>.s_per_1000``: seconds to load a long-format CSV of ``n`` movements
  (the seed-0 synthetic library, 458 movements of about 100 samples, repeated 1, 10 and
  20 times), per 1000 movements. Reference: the same figure for the smallest file, so a
  ratio near 1 at every size means linear time (the loader once took 0.36 s, 11 s and
  63 s for 458, 4 580 and 9 160 movements: ratios 1, 3.9 and 22).
"""

from __future__ import annotations

import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from cogblocks.data.loaders import load_csv, save_csv
from cogblocks.data.reach import generate_reach_library


def _seconds(path: Path, repeats: int) -> float:
    """Best of ``repeats`` loads: the least disturbed by the other work on a shared machine."""
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        load_csv(path)
        best = min(best, time.perf_counter() - start)
    return best


def run(quick: bool = False) -> Iterator[dict]:
    """Yield seconds per 1000 movements at each library size."""
    library = generate_reach_library(0)
    copies = (1, 10) if quick else (1, 10, 20)
    reference = None
    with tempfile.TemporaryDirectory() as folder:
        for k in copies:
            n = k * len(library)
            path = Path(folder) / f"library_{n}.csv"
            save_csv(library.subset(np.tile(np.arange(len(library)), k)), path)
            value = 1000.0 * _seconds(path, repeats=3 if k == 1 else 1) / n
            reference = value if reference is None else reference
            yield {
                "name": f"loaders.csv.{n}.s_per_1000",
                "value": value,
                "unit": "s/1000 movements",
                "reference": reference,
                "ratio": value / reference,
                "movements": n,
            }
