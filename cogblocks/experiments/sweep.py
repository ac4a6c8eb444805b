"""Parameter sweeps: one run per parameter combination × seed, serially, on joblib's loky or on Dask.

Each task builds a diagram with ``build(**params, seed=seed)``, runs it with
``Simulator(diagram, dt, probes=probes).run(duration=duration)`` (or ``n_steps=``), and measures the
trace with ``measure(trace)``; ``build`` may instead return a ready run function ``f() -> Trace``,
which is then called as it is. The seeds come from ``numpy.random.SeedSequence(root_seed).spawn``,
one per replicate, and every task is a pure function of its parameters and seed, so the result does
not depend on the backend, the number of workers or the order in which tasks finish.
"""

from __future__ import annotations

import itertools
import os
import sys
import traceback
import warnings
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from cogblocks.sim import Diagram, Simulator, Trace
from cogblocks.sim.timing import BASE_STEP

__all__ = ["BACKENDS", "RunSpec", "SweepWarning", "grid_points", "save_results", "sweep", "sweep_seeds"]

BACKENDS = ("serial", "loky", "dask")

#: Batches per worker: enough for the load to even out, few enough that a batch's overhead is small.
BATCHES_PER_WORKER = 4


class SweepWarning(UserWarning):
    """Some tasks of a sweep failed; their rows carry the error, the others are kept."""


@dataclass(frozen=True)
class RunSpec:
    """How every task of a sweep runs: what it builds, how long, and what it measures."""

    build: Callable[..., Diagram | Callable[[], Trace]]
    measure: Callable[[Trace], Mapping[str, Any]]
    dt: float = BASE_STEP
    duration: float | None = None
    n_steps: int | None = None
    probes: Sequence[str] | Mapping[str, str] | None = None


@dataclass(frozen=True)
class _Task:
    index: int
    params: dict[str, Any]
    replicate: int
    seed: int


def grid_points(grid: Mapping[str, Sequence[Any]] | Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """The parameter combinations of ``grid``.

    A mapping of name to values gives their Cartesian product (the first name varies slowest);
    a sequence of mappings is taken as the list of combinations itself.
    """
    if isinstance(grid, Mapping):
        for name, values in grid.items():
            if isinstance(values, (str, bytes)) or not isinstance(values, Iterable):
                raise ValueError(f"sweep: grid[{name!r}] must be a sequence of values, got {values!r}")
        names = list(grid)
        return [dict(zip(names, combo, strict=True)) for combo in itertools.product(*(list(grid[n]) for n in names))]
    points = [dict(p) for p in grid]
    if not all(isinstance(p, dict) for p in points):
        raise ValueError("sweep: grid must be a mapping of name to values or a sequence of mappings")
    return points


def sweep_seeds(n: int, root_seed: int = 0) -> list[int]:
    """The seeds of replicates ``0 .. n-1``: ``SeedSequence(root_seed).spawn(n)``, each as a 32-bit int."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"sweep: seeds must be an integer >= 1 or a sequence of ints, got {n!r}")
    return [int(child.generate_state(1)[0]) for child in np.random.SeedSequence(root_seed).spawn(int(n))]


def _run_task(spec: RunSpec, task: _Task) -> tuple[dict[str, Any], str | None]:
    built = spec.build(**task.params, seed=task.seed)
    if isinstance(built, Diagram):
        sim = Simulator(built, spec.dt, probes=spec.probes, progress=False)
        trace = sim.run(spec.duration, n_steps=spec.n_steps)
    elif callable(built):
        trace = built()
    else:
        raise TypeError(f"build must return a Diagram or a run function, got {type(built).__name__}")
    figures = spec.measure(trace)
    if not isinstance(figures, Mapping):
        raise TypeError(f"measure must return a mapping of figures, got {type(figures).__name__}")
    return dict(figures), None


def run_batch(spec: RunSpec, tasks: list[_Task]) -> list[tuple[int, dict[str, Any], str | None]]:
    """Run tasks one after the other; a failing task gives its error text instead of figures."""
    results = []
    for task in tasks:
        try:
            figures, error = _run_task(spec, task)
        except Exception as exc:  # noqa: BLE001 - one task's failure must not lose the others
            figures, error = {}, "".join(traceback.format_exception_only(type(exc), exc)).strip()
        results.append((task.index, figures, error))
    return results


def sweep(
    build: Callable[..., Diagram | Callable[[], Trace]],
    grid: Mapping[str, Sequence[Any]] | Sequence[Mapping[str, Any]],
    *,
    measure: Callable[[Trace], Mapping[str, Any]],
    seeds: int | Sequence[int] = 1,
    root_seed: int = 0,
    duration: float | None = None,
    n_steps: int | None = None,
    dt: float = BASE_STEP,
    probes: Sequence[str] | Mapping[str, str] | None = None,
    backend: str = "loky",
    n_jobs: int | None = None,
    client: Any = None,
    batch_size: int | None = None,
    progress: bool | None = None,
) -> pd.DataFrame:
    """Run ``build`` over every combination of ``grid`` and every seed; one row per run.

    Parameters
    ----------
    build : callable
        ``build(**params, seed=seed)`` returns a :class:`~cogblocks.sim.Diagram`, run for
        ``duration`` seconds (or ``n_steps`` ticks) at ``dt`` with ``probes`` recorded besides its
        ``Probe`` blocks, or a function ``f() -> Trace`` that runs by itself. Must be picklable
        for ``loky`` and ``dask`` (a module-level function or a ``functools.partial`` of one).
    grid : mapping of str to sequence, or sequence of mappings
        See :func:`grid_points`.
    measure : callable
        ``measure(trace)`` returns a mapping of figure name to number.
    seeds : int or sequence of int
        Number of replicates (seeds from :func:`sweep_seeds` of ``root_seed``) or the seeds themselves.
    backend : {"loky", "serial", "dask"}
        ``"loky"``: local processes through joblib. ``"dask"``: a ``dask.distributed`` cluster, the
        one of ``client`` (a ``Client`` or a scheduler address) or a local one of ``n_jobs`` workers,
        on 127.0.0.1, started and closed here.
    n_jobs : int, optional
        Workers (all cores by default).
    batch_size : int, optional
        Tasks per batch sent to a worker; by default about :data:`BATCHES_PER_WORKER` batches per worker.
    progress : bool, optional
        A progress bar over tasks; by default when stderr is a terminal.

    Returns
    -------
    pandas.DataFrame
        Long form, in grid order then seed order: the parameters, ``replicate``, ``seed``, the
        figures, and ``error`` (``None``, or the exception of a failed task, whose figures are
        missing). Failures are also listed in ``df.attrs["failures"]`` and warned about
        (:class:`SweepWarning`).
    """
    if backend not in BACKENDS:
        raise ValueError(f"sweep: backend must be one of {list(BACKENDS)}, got {backend!r}")
    if not callable(build) or not callable(measure):
        raise ValueError("sweep: build and measure must be callables")
    seed_list = sweep_seeds(seeds, root_seed) if isinstance(seeds, (int, np.integer)) else [int(s) for s in seeds]
    if not seed_list:
        raise ValueError("sweep: seeds must not be empty")
    points = grid_points(grid)
    tasks = [
        _Task(i * len(seed_list) + j, point, j, seed)
        for i, point in enumerate(points)
        for j, seed in enumerate(seed_list)
    ]
    spec = RunSpec(build, measure, dt, duration, n_steps, probes)
    workers = n_jobs or os.cpu_count() or 1
    size = batch_size or max(1, -(-len(tasks) // (BATCHES_PER_WORKER * workers)))
    batches = [tasks[i : i + size] for i in range(0, len(tasks), size)]
    show = progress if progress is not None else sys.stderr.isatty() and not os.environ.get("CI")
    outcomes: dict[int, tuple[dict[str, Any], str | None]] = {}
    with _progress(len(tasks), show) as bar:
        for batch_results in _execute(backend, spec, batches, workers, client):
            for index, figures, error in batch_results:
                outcomes[index] = (figures, error)
            bar(len(batch_results))
    return _frame(tasks, outcomes)


def _execute(
    backend: str, spec: RunSpec, batches: list[list[_Task]], workers: int, client: Any
) -> Iterator[list[tuple[int, dict[str, Any], str | None]]]:
    if backend == "serial" or not batches:
        for batch in batches:
            yield run_batch(spec, batch)
        return
    if backend == "loky":
        from joblib import Parallel, delayed

        parallel = Parallel(n_jobs=workers, backend="loky", return_as="generator_unordered")
        yield from parallel(delayed(run_batch)(spec, batch) for batch in batches)
        return
    yield from _execute_dask(spec, batches, workers, client)


def _execute_dask(
    spec: RunSpec, batches: list[list[_Task]], workers: int, client: Any
) -> Iterator[list[tuple[int, dict[str, Any], str | None]]]:
    from distributed import Client, LocalCluster, as_completed

    own_cluster = own_client = None
    if client is None:
        own_cluster = LocalCluster(
            n_workers=workers, threads_per_worker=1, host="127.0.0.1", dashboard_address=None, processes=True
        )
        client = own_client = Client(own_cluster)
    elif isinstance(client, str):
        client = own_client = Client(client)
    try:
        spec_future = client.scatter(spec, broadcast=True)
        futures = [client.submit(run_batch, spec_future, batch, pure=False) for batch in batches]
        for future in as_completed(futures):
            yield future.result()
    finally:
        if own_client is not None:
            own_client.close()
        if own_cluster is not None:
            own_cluster.close()


class _progress:
    """A tqdm bar over tasks when shown, else nothing."""

    def __init__(self, total: int, show: bool) -> None:
        self.total, self.show, self.bar = total, show, None

    def __enter__(self) -> Callable[[int], None]:
        if self.show:
            from tqdm import tqdm

            self.bar = tqdm(total=self.total, unit="run", desc="sweep", leave=False)
            return self.bar.update
        return lambda n: None

    def __exit__(self, *exc: Any) -> None:
        if self.bar is not None:
            self.bar.close()


def _frame(tasks: list[_Task], outcomes: dict[int, tuple[dict[str, Any], str | None]]) -> pd.DataFrame:
    figure_names: list[str] = []
    for task in tasks:
        for name in outcomes[task.index][0]:
            if name not in figure_names:
                figure_names.append(name)
    rows = []
    failures = []
    for task in tasks:
        figures, error = outcomes[task.index]
        row = {**task.params, "replicate": task.replicate, "seed": task.seed}
        row.update({name: figures.get(name, np.nan) for name in figure_names})
        row["error"] = error
        rows.append(row)
        if error is not None:
            failures.append({**task.params, "seed": task.seed, "error": error})
    df = pd.DataFrame(rows)
    df.attrs["failures"] = failures
    if failures:
        first = failures[0]
        warnings.warn(
            f"{len(failures)} of {len(tasks)} sweep tasks failed; the first: {first}", SweepWarning, stacklevel=3
        )
    return df


def save_results(df: pd.DataFrame, path: str | os.PathLike[str]) -> Path:
    """Write a sweep's DataFrame to ``.parquet`` (pyarrow) or ``.csv``; returns the path."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".parquet":
        df.to_parquet(path, index=False)
    elif suffix == ".csv":
        df.to_csv(path, index=False)
    else:
        raise ValueError(f"{path}: sweep results are saved as .parquet or .csv, got {suffix or 'no suffix'!r}")
    return path
