"""The real-time runner: one diagram tick per period of the wall clock, paced on deadlines."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from cogblocks.sim import CompiledDiagram, Trace

__all__ = ["RealtimeReport", "run_realtime", "save_report"]

# Sleep until this close to a deadline, then spin: a sleep may wake up a fraction of a millisecond late.
_SPIN_S = 0.0005


@dataclass
class RealtimeReport:
    """What a real-time run did.

    Attributes
    ----------
    ticks : int
        Ticks run.
    late_ticks : int
        Ticks that finished after the end of their slot (their deadline plus one period).
    overruns : int
        Ticks whose computation alone took longer than one period.
    tick_ms : numpy.ndarray
        Computation time of each tick (the diagram's step, LSL pulls and pushes included), in ms.
    start_ms : numpy.ndarray
        How long after its deadline each tick started, in ms.
    samples_in, samples_out : int
        Samples received by the diagram's inlets and sent by its outlets and senders during the run.
    max_age_ms : float
        Largest finite ``age_ms`` that an inlet reported (NaN if none did).
    interrupted : bool
        Whether Ctrl-C stopped the run early.
    trace : Trace or None
        The diagram's top-level outputs at every tick, if recorded.
    raw : dict
        Per inlet (by block path), the ``(t, x)`` of every received sample, if recorded.
    """

    ticks: int
    late_ticks: int
    overruns: int
    tick_ms: np.ndarray
    start_ms: np.ndarray
    samples_in: int
    samples_out: int
    max_age_ms: float
    interrupted: bool = False
    trace: Trace | None = None
    raw: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)

    def summary(self) -> dict[str, Any]:
        """The figures of the run as plain numbers (what ``cogblocks live --json`` prints)."""

        def pct(q: float) -> float:
            return float(np.percentile(self.tick_ms, q)) if len(self.tick_ms) else math.nan

        return {
            "ticks": self.ticks,
            "late_ticks": self.late_ticks,
            "tick_ms_p50": pct(50),
            "tick_ms_p99": pct(99),
            "samples_in": self.samples_in,
            "samples_out": self.samples_out,
            "max_age_ms": self.max_age_ms,
        }


def _wait_until(deadline: float) -> None:
    remaining = deadline - time.perf_counter()
    if remaining > _SPIN_S:
        time.sleep(remaining - _SPIN_S)
    while time.perf_counter() < deadline:
        pass


def _counter(blocks: list[Any], name: str) -> int:
    return sum(int(getattr(b, name)) for b in blocks if hasattr(b, name))


def run_realtime(
    compiled: CompiledDiagram,
    duration: float,
    rate: float = 100.0,
    *,
    record: bool = False,
    record_raw: bool = False,
    save: str | Path | None = None,
    scope: Any = None,
    recorder: Any = None,
) -> RealtimeReport:
    """Run a compiled diagram in real time: tick ``k`` starts at ``start + k / rate`` on ``perf_counter``.

    Ticks are paced on deadlines, not on sleeps, so the run never drifts: a late tick runs as soon
    as it can and the next one keeps its own deadline. Ctrl-C stops the run after the current tick;
    what was recorded is returned (and saved, with ``save``).

    Parameters
    ----------
    compiled : CompiledDiagram
        A diagram without top-level inputs (its inlets feed it), compiled with ``dt = 1 / rate``.
    duration : float
        Seconds to run (> 0): ``round(duration * rate)`` ticks.
    rate : float
        Ticks per second.
    record : bool
        Record the diagram's top-level outputs at every tick into ``report.trace``.
    record_raw : bool
        Record every sample that the diagram's :class:`~cogblocks.live.LSLInlet` blocks receive.
    save : str or Path, optional
        Write the report to this ``.npz`` file when the run ends (see :func:`save_report`).
    scope : Scope, optional
        A :class:`~cogblocks.live.scope.Scope` that each tick's outputs are pushed to (its page draws them).
    recorder : SessionRecorder, optional
        A :class:`~cogblocks.live.session.SessionRecorder`, started here and told of every tick; it
        writes the session file as the run goes (the caller closes it).

    Returns
    -------
    RealtimeReport
    """
    if not (isinstance(duration, (int, float)) and math.isfinite(duration) and duration > 0):
        raise ValueError(f"run_realtime: duration must be a positive number of seconds, got {duration!r}")
    if not (isinstance(rate, (int, float)) and math.isfinite(rate) and rate > 0):
        raise ValueError(f"run_realtime: rate must be a positive number of ticks per second, got {rate!r}")
    if abs(compiled.dt * rate - 1.0) > 1e-9:
        raise ValueError(
            f"run_realtime: the diagram was compiled with dt = {compiled.dt} s, which does not tick at {rate} Hz"
        )
    if compiled.input_names:
        raise ValueError(
            f"run_realtime: the diagram has top-level inputs {list(compiled.input_names)}; a live diagram "
            "takes its inputs from inlet blocks"
        )
    blocks = list(compiled.blocks.values())
    inlets = {path: b for path, b in compiled.blocks.items() if hasattr(b, "samples_in")}
    if record_raw:
        for inlet in inlets.values():
            inlet.record = True
    ages = [b.age_ms.value for b in inlets.values() if hasattr(b, "age_ms")]
    in_before, out_before = _counter(blocks, "samples_in"), _counter(blocks, "samples_out")
    n = round(duration * rate)
    period = 1.0 / rate
    tick_s, start_s = np.zeros(n), np.zeros(n)
    rows: list[dict[str, Any]] = []
    k0 = compiled.k
    late = overruns = done = 0
    max_age = -np.inf
    interrupted = False
    if recorder is not None:
        recorder.start()
    start = time.perf_counter()
    try:
        for i in range(n):
            deadline = start + i * period
            _wait_until(deadline)
            began = time.perf_counter()
            out = compiled.step()
            ended = time.perf_counter()
            tick_s[i], start_s[i] = ended - began, began - deadline
            is_late = ended > deadline + period
            late += is_late
            overruns += ended - began > period
            if scope is not None:
                scope.push((k0 + i) * compiled.dt, out, is_late)
            if recorder is not None:
                recorder.ticked(1e3 * tick_s[i], 1e3 * start_s[i], is_late)
            for age in ages:
                if np.isfinite(age) and age > max_age:
                    max_age = float(age)
            if record:
                rows.append(out)
            done = i + 1
    except KeyboardInterrupt:
        interrupted = True
    trace = _trace(rows, compiled, k0) if record else None
    raw = {path: b.raw() for path, b in inlets.items() if getattr(b, "record", False)}
    report = RealtimeReport(
        ticks=done,
        late_ticks=int(late),
        overruns=int(overruns),
        tick_ms=1e3 * tick_s[:done],
        start_ms=1e3 * start_s[:done],
        samples_in=_counter(blocks, "samples_in") - in_before,
        samples_out=_counter(blocks, "samples_out") - out_before,
        max_age_ms=max_age if np.isfinite(max_age) else math.nan,
        interrupted=interrupted,
        trace=trace,
        raw=raw,
    )
    if save is not None:
        save_report(report, save)
    return report


def _trace(rows: list[dict[str, Any]], compiled: CompiledDiagram, k0: int) -> Trace:
    names = compiled.output_names
    signals = {name: np.array([row[name] for row in rows]) for name in names}
    units = {name: compiled.output_port(name).spec.unit for name in names}
    return Trace((k0 + np.arange(len(rows))) * compiled.dt, signals, units)


def save_report(report: RealtimeReport, path: str | Path) -> Path:
    """Write a report to a NumPy ``.npz`` file and return its path.

    Keys: ``tick_ms``, ``start_ms``, ``summary`` (a JSON string), and when recorded ``t`` with one
    array per output of the trace, and ``raw/<inlet>/t`` and ``raw/<inlet>/x`` per inlet.
    """
    import json

    path = Path(path)
    arrays: dict[str, np.ndarray] = {
        "tick_ms": report.tick_ms,
        "start_ms": report.start_ms,
        "summary": np.array(json.dumps({**report.summary(), "interrupted": report.interrupted})),
    }
    if report.trace is not None:
        arrays["t"] = report.trace.t
        arrays.update({name: report.trace[name] for name in report.trace})
    for inlet, (t, x) in report.raw.items():
        arrays[f"raw/{inlet}/t"] = t
        arrays[f"raw/{inlet}/x"] = x
    with path.open("wb") as f:
        np.savez(f, **arrays)
    return path
