"""Load a saved run for ``cogblocks view``: a trace saved by ``--save`` (.npz) or a recorded session (.xdf)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

__all__ = ["load_run"]

_NOT_SIGNALS = {"t", "tick_ms", "start_ms", "summary"}


def load_run(path: str | os.PathLike) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, str], np.ndarray]:
    """The times, outputs, units and late-tick flags of a saved run.

    A ``.npz`` file is a report saved by ``cogblocks live --save`` (or ``replay --save``); its units are not
    kept. A ``.xdf`` file is a session recorded by ``cogblocks live --record``: the diagram it names is
    replayed on it (:func:`~cogblocks.live.replay.replay_session`), which gives every output of the live run.

    Raises
    ------
    ValueError
        Naming the file: missing, of another kind, or without a trace.
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix == ".npz":
        with np.load(path) as run:
            if "t" not in run.files:
                raise ValueError(f"{path}: holds no trace (save it with --save from cogblocks live or replay)")
            t = run["t"]
            signals = {k: run[k] for k in run.files if k not in _NOT_SIGNALS and not k.startswith("raw/")}
            dt = float(t[1] - t[0]) if len(t) > 1 else 0.01
            late = (run["start_ms"] + run["tick_ms"] > 1e3 * dt) if "tick_ms" in run.files else np.zeros(len(t), bool)
        return t, signals, {k: "" for k in signals}, late[: len(t)]
    if suffix == ".xdf":
        from cogblocks.live.ready import live_diagram
        from cogblocks.live.replay import load_session, replay_session

        session = load_session(path)
        if "diagram" not in session.options:
            raise ValueError(f"{path}: names no ready diagram to replay (record it with cogblocks live --record)")
        report = replay_session(live_diagram(session.options), session)
        trace = report.trace
        signals = {name: trace[name] for name in trace}
        return trace.t, signals, {name: trace.units.get(name, "") for name in trace}, session.run_figures()["late"]
    raise ValueError(f"{path}: cogblocks view shows .npz traces and .xdf sessions, not {suffix or 'this file'}")
