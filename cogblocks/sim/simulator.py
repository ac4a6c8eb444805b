"""The Simulator: runs a compiled diagram for a duration and records probes."""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from cogblocks.sim.compiled import CompiledDiagram
from cogblocks.sim.diagram import Diagram
from cogblocks.sim.errors import DiagramError
from cogblocks.sim.memory import check_memory
from cogblocks.sim.timing import BASE_STEP
from cogblocks.sim.trace import Trace

__all__ = ["Simulator"]

_PROGRESS_MIN_STEPS = 20_000


class Simulator:
    """Run a diagram with a fixed base step and collect a :class:`Trace`.

    Parameters
    ----------
    diagram : Diagram or CompiledDiagram
        What to run; a ``Diagram`` is compiled with ``dt``.
    dt : float
        Base step in seconds (10 ms by default). Ignored for a ``CompiledDiagram``.
    probes : sequence of str or mapping of str to str, optional
        Output ports to record, as dotted paths (``"group.theta"``), or a mapping
        from trace name to path. Every ``Probe`` block is recorded as well, under
        its path.
    decimate : int
        Record every ``decimate``-th tick (1 = every tick).
    progress : bool, optional
        Show a progress bar; by default only on long runs attached to a
        terminal and never when the ``CI`` environment variable is set.
    batch : int, optional
        Run that many independent runs at once (``diagram.compile(dt, batch=batch)``, see
        :mod:`cogblocks.sim.batch`): inputs and recorded signals then have a batch axis of that
        many rows after the time axis. For a ``CompiledDiagram`` it must be the plan's own.

    Notes
    -----
    Successive :meth:`run` calls continue from where the previous one stopped;
    call :meth:`reset` to start again from tick 0. Two simulators of one diagram
    are independent (the newer runs the diagram's blocks, the older continues
    on a copy; see :meth:`Diagram.compile`); run one simulator from one thread
    at a time.
    """

    def __init__(
        self,
        diagram: Diagram | CompiledDiagram,
        dt: float = BASE_STEP,
        *,
        probes: Sequence[str] | Mapping[str, str] | None = None,
        decimate: int = 1,
        progress: bool | None = None,
        batch: int | None = None,
    ) -> None:
        if isinstance(diagram, CompiledDiagram):
            if batch is not None and batch != diagram.batch:
                raise ValueError(f"Simulator: batch={batch!r}, but the compiled diagram runs batch={diagram.batch!r}")
            self.compiled = diagram
        elif isinstance(diagram, Diagram):
            self.compiled = diagram.compile(dt, batch=batch)
        else:
            raise TypeError(f"Simulator needs a Diagram or CompiledDiagram, got {type(diagram).__name__}")
        if not isinstance(decimate, (int, np.integer)) or decimate < 1:
            raise ValueError(f"decimate must be an integer >= 1, got {decimate!r}")
        self.decimate = int(decimate)
        self.progress = progress
        self._probes = self._resolve_probes(probes)

    def _resolve_probes(self, probes) -> dict[str, str | None]:
        """Probe names mapped to output paths, or to None for a ``Probe`` block (recorded at its input)."""
        from cogblocks.sim.probe import Probe

        found: dict[str, str | None] = {path: None for path, b in self.compiled.blocks.items() if isinstance(b, Probe)}
        if probes is None:
            return found
        pairs = probes.items() if isinstance(probes, Mapping) else ((p, p) for p in probes)
        for name, path in pairs:
            if name in found:
                raise DiagramError(f"probe name {name!r} is used twice")
            try:
                self.compiled.output_port(path)
            except KeyError as exc:
                raise DiagramError(str(exc.args[0])) from None
            found[name] = path
        return found

    def _probe_arrays(self) -> dict[str, tuple[np.ndarray, str]]:
        """The recorded arrays and their units, looked up for each run (a plan may have moved to a copy)."""
        compiled = self.compiled
        ports = {
            name: compiled.blocks[name].u if path is None else compiled.output_port(path)
            for name, path in self._probes.items()
        }
        return {name: (port.value, port.spec.unit or "") for name, port in ports.items()}

    @property
    def batch(self) -> int | None:
        """Runs at once (``None``: no batch axis)."""
        return self.compiled.batch

    @property
    def dt(self) -> float:
        """The base step in seconds."""
        return self.compiled.dt

    @property
    def time(self) -> float:
        """Time of the next tick in seconds."""
        return self.compiled.time

    def reset(self) -> None:
        """Rewind the diagram to tick 0 and its initial state."""
        self.compiled.reset()

    def state_dict(self) -> dict[str, Any]:
        """Snapshot of the whole diagram; see :meth:`CompiledDiagram.state_dict`."""
        return self.compiled.state_dict()

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """Restore a snapshot taken with :meth:`state_dict`; one that does not fit changes nothing."""
        self.compiled.load_state_dict(state)

    def save_state(self, path: str | os.PathLike) -> None:
        """Write the snapshot to an ``.npz`` file; see :meth:`CompiledDiagram.save_state`."""
        self.compiled.save_state(path)

    def load_state(self, path: str | os.PathLike) -> None:
        """Load a snapshot file written by :meth:`save_state`."""
        self.compiled.load_state(path)

    def run(
        self,
        duration: float | None = None,
        *,
        n_steps: int | None = None,
        inputs: Mapping[str, Any] | None = None,
        include_end: bool = False,
    ) -> Trace:
        """Run for ``duration`` seconds (``round(duration / dt)`` ticks) or ``n_steps`` ticks.

        A run simulates *ticks*, not instants: ``run(duration=T)`` from time ``t0``
        runs the ``T / dt`` ticks at ``t0, t0 + dt, …, t0 + T - dt`` and stops
        with the clock at ``t0 + T``, so the next run continues at ``t0 + T`` and
        two runs of ``T`` give exactly one run of ``2 T``. (python-control and
        Simulink report the end point too: ``include_end=True`` runs one more tick,
        for ``T / dt + 1`` samples ending at ``t0 + T``.)

        Parameters
        ----------
        duration : float, optional
            Seconds to simulate; must be a whole number of base steps.
        n_steps : int, optional
            Ticks to simulate (give this or ``duration``).
        inputs : mapping, optional
            Values of the top-level diagram inputs: an array with one row per tick,
            a callable ``f(t) -> value``, or a constant.
        include_end : bool
            With ``duration``, also run the tick at the end time ``t0 + T``.

        Returns
        -------
        Trace
            The probed signals at every ``decimate``-th tick of this run.
        """
        n = self._n_steps(duration, n_steps)
        if include_end:
            if duration is None:
                raise ValueError("include_end applies to run(duration=...); with n_steps, ask for the ticks you want")
            n += 1
        compiled = self.compiled
        k0 = compiled.k
        feed = self._feeder(inputs or {}, k0, n)
        n_rec = (n + self.decimate - 1) // self.decimate
        probes = self._probe_arrays()
        for name, (arr, _) in probes.items():
            check_memory(
                n_rec * arr.nbytes,
                f"probe {name!r} ({arr.size} values over {n_rec} recorded ticks)",
                "record fewer ticks (Simulator(..., decimate=k) keeps every k-th), a shorter run, or probe less",
            )
        buffers = {name: np.empty((n_rec,) + arr.shape, dtype=arr.dtype) for name, (arr, _) in probes.items()}
        record = self._recorder(buffers, probes, k0)
        show = self.progress
        if show is None:
            show = n >= _PROGRESS_MIN_STEPS and sys.stderr.isatty() and not os.environ.get("CI")
        if show:
            from tqdm import tqdm

            chunk = max(1000, n // 200)
            with tqdm(total=n, unit="tick", desc="simulating", leave=False) as bar:
                done = 0
                while done < n:
                    m = min(chunk, n - done)
                    compiled.advance(m, record, feed)
                    done += m
                    bar.update(m)
        else:
            compiled.advance(n, record, feed)
        t = (k0 + np.arange(n_rec) * self.decimate) * compiled.dt
        return Trace(t, buffers, {name: unit for name, (_, unit) in probes.items()}, batch=compiled.batch)

    def _n_steps(self, duration: float | None, n_steps: int | None) -> int:
        if (duration is None) == (n_steps is None):
            raise ValueError("give exactly one of duration (seconds) or n_steps (ticks)")
        if n_steps is not None:
            if not isinstance(n_steps, (int, np.integer)) or n_steps < 0:
                raise ValueError(f"n_steps must be a non-negative integer, got {n_steps!r}")
            return int(n_steps)
        assert duration is not None
        return self.steps(duration)

    def steps(self, duration: float) -> int:
        """Number of base ticks in ``duration`` seconds; refuses a duration that is not a whole number of steps."""
        if not np.isfinite(duration) or duration < 0:
            raise ValueError(f"duration must be a non-negative number of seconds, got {duration!r}")
        n = round(duration / self.dt)
        if abs(n * self.dt - duration) > 1e-9 * max(1.0, duration):
            raise ValueError(f"duration {duration} s is not a whole number of base steps of {self.dt} s")
        return n

    def _feeder(self, inputs: Mapping[str, Any], k0: int, n: int) -> Callable[[int], None] | None:
        self.compiled._check_input_names(inputs)
        missing = [name for name in self.compiled.input_names if name not in inputs]
        if missing:
            raise ValueError(f"run() needs values for the diagram inputs {missing}")
        if not inputs:
            return None
        feeders: list[Callable[[int], None]] = []
        dt = self.compiled.dt
        for name, source in inputs.items():
            target = self.compiled._external[name]
            if callable(source):
                feeders.append(_callable_feeder(name, source, target, dt))
                continue
            try:
                arr = np.asarray(source, dtype=target.dtype)
            except (TypeError, ValueError) as exc:
                raise ValueError(
                    f"input {name!r}: expected {target.dtype} values of shape {target.shape} (a constant) or "
                    f"({n}, {', '.join(map(str, target.shape))}) (one row per tick), got {source!r:.80}: {exc}"
                ) from None
            if arr.shape == target.shape:
                target[...] = arr
                continue
            if arr.shape[1:] != target.shape or len(arr) < n:
                raise ValueError(
                    f"input {name!r}: expected a constant of shape {target.shape} or an array of shape "
                    f"({n}, {', '.join(map(str, target.shape))}), got {arr.shape}"
                )
            feeders.append(lambda k, a=target, src=arr: a.__setitem__(Ellipsis, src[k - k0]))
        if not feeders:
            return None
        if len(feeders) == 1:
            return feeders[0]

        def feed(k: int) -> None:
            for f in feeders:
                f(k)

        return feed

    def _recorder(
        self, buffers: dict[str, np.ndarray], probes: dict[str, tuple[np.ndarray, str]], k0: int
    ) -> Callable[[int], None] | None:
        pairs = [(buffers[name], arr) for name, (arr, _) in probes.items()]
        if not pairs:
            return None
        d = self.decimate
        if len(pairs) == 1 and d == 1:
            buf, arr = pairs[0]

            def record_one(k: int) -> None:
                buf[k - k0] = arr

            return record_one

        def record(k: int) -> None:
            i, r = divmod(k - k0, d)
            if r == 0:
                for b, a in pairs:
                    b[i] = a

        return record


def _callable_feeder(name: str, f: Callable[[float], Any], target: np.ndarray, dt: float) -> Callable[[int], None]:
    """Feed ``target`` with ``f(t)``, refusing a value of another shape (no silent broadcasting)."""
    shape = target.shape

    def feed(k: int) -> None:
        value = f(k * dt)
        if np.shape(value) != shape:
            raise ValueError(
                f"input {name!r}: the function returned a value of shape {np.shape(value)} at t = {k * dt:g} s, "
                f"the input expects shape {shape}"
            )
        target[...] = value

    return feed
