"""Load a saved run for ``cogblocks view``: a trace saved by ``--save`` (.npz), a recorded session or any XDF file.

A session that ``cogblocks live --record`` wrote is replayed through its diagram, which gives every output
of the live run. Any other XDF file (LabRecorder's, with streams of other programs) is read with pyxdf,
its clocks synchronised: each numeric stream is one signal, its channels linearly interpolated onto one
grid (10 ms, coarser for recordings of more than 200 000 steps), NaN before its first and after its last
sample. What cannot be drawn (text streams such as event markers, streams without samples) is named.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from cogblocks.sim.reading import open_npz
from cogblocks.sim.timing import BASE_STEP

__all__ = ["load_run", "load_xdf_streams"]

_NOT_SIGNALS = {"t", "tick_ms", "start_ms", "summary"}
_MAX_POINTS = 200_000  # per signal, what the page still draws smoothly


def load_run(
    path: str | os.PathLike, skipped: list[str] | None = None
) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, str], np.ndarray]:
    """The times, outputs, units and late-tick flags of a saved run.

    A ``.npz`` file is a report saved by ``cogblocks live --save`` (or ``replay --save``); its units are not
    kept. A ``.xdf`` file is a session recorded by ``cogblocks live --record``: the diagram it names is
    replayed on it (:func:`~cogblocks.live.replay.replay_session`); any other XDF file is read as
    :func:`load_xdf_streams` reads it.

    Parameters
    ----------
    skipped : list, optional
        Receives one line per stream that cannot be shown, naming it and why.

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
        with open_npz(path, "saved run") as run:
            if "t" not in run.files:
                raise ValueError(f"{path}: holds no trace (save it with --save from cogblocks live or replay)")
            t = run["t"]
            signals = {k: run[k] for k in run.files if k not in _NOT_SIGNALS and not k.startswith("raw/")}
            dt = float(t[1] - t[0]) if len(t) > 1 else BASE_STEP
            late = (run["start_ms"] + run["tick_ms"] > 1e3 * dt) if "tick_ms" in run.files else np.zeros(len(t), bool)
        return t, signals, {k: "" for k in signals}, late[: len(t)]
    if suffix == ".xdf":
        from cogblocks.live.ready import live_diagram
        from cogblocks.live.replay import NotASession, load_session, replay_session

        try:
            session = load_session(path)
        except NotASession:
            return load_xdf_streams(path, skipped)
        if "diagram" not in session.options:
            raise ValueError(f"{path}: names no ready diagram to replay (record it with cogblocks live --record)")
        report = replay_session(live_diagram(session.options), session)
        trace = report.trace
        signals = {name: trace[name] for name in trace}
        late = session.run_figures()["late"][: len(trace.t)]
        return trace.t, signals, {name: trace.units.get(name, "") for name in trace}, late
    raise ValueError(f"{path}: cogblocks view shows .npz traces and .xdf files, not {suffix or 'this file'}")


def _first(value: Any, default: str = "") -> str:
    while isinstance(value, list):
        value = value[0] if value else None
    return default if value is None else str(value)


def _units(info: dict[str, Any], channels: int) -> str:
    """The channels' unit when they all declare the same one, else ''."""
    desc = (info.get("desc") or [None])[0]
    found = ((desc or {}).get("channels") or [None])[0] if isinstance(desc, dict) else None
    units = {_first(c.get("unit")) for c in (found or {}).get("channel", [])} if isinstance(found, dict) else set()
    return units.pop() if len(units) == 1 and channels else ""


def load_xdf_streams(
    path: str | os.PathLike, skipped: list[str] | None = None
) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, str], np.ndarray]:
    """Every numeric stream of an XDF file on one time grid: ``(t, signals, units, late)`` as :func:`load_run`.

    ``t`` starts at 0 at the first sample of any stream; ``late`` is all False (no run to be late).

    Raises
    ------
    ValueError
        Naming the file if pyxdf cannot read it or no stream holds numbers to draw.
    """
    import pyxdf

    path = Path(path)
    try:
        streams, _ = pyxdf.load_xdf(str(path))
    except Exception as exc:  # pyxdf raises what its parser meets: struct, XML and value errors
        raise ValueError(f"{path}: not a readable XDF file ({type(exc).__name__}: {exc})") from None
    notes = [] if skipped is None else skipped
    kept: dict[str, tuple[np.ndarray, np.ndarray, str]] = {}
    for stream in streams:
        info = stream["info"]
        name = _first(info.get("name"), "stream")
        stamps = np.asarray(stream["time_stamps"], dtype=np.float64)
        if _first(info.get("channel_format")) == "string":
            notes.append(f"stream {name!r}: text ({len(stamps)} samples), not drawn")
            continue
        if len(stamps) < 2:
            notes.append(f"stream {name!r}: {len(stamps)} sample(s), nothing to draw")
            continue
        values = np.asarray(stream["time_series"], dtype=np.float64).reshape(len(stamps), -1)
        order = np.argsort(stamps, kind="stable")
        key = name if name not in kept else f"{name} ({len(kept) + 1})"
        kept[key] = (stamps[order], values[order], _units(info, values.shape[1]))
    if not kept:
        raise ValueError(f"{path}: no stream of numbers to show ({'; '.join(notes) or 'the file holds no streams'})")
    start = min(s[0] for s, _, _ in kept.values())
    stop = max(s[-1] for s, _, _ in kept.values())
    step = max(BASE_STEP, (stop - start) / _MAX_POINTS)
    grid = start + step * np.arange(int(np.floor((stop - start) / step)) + 1)
    signals = {
        key: np.column_stack([np.interp(grid, s, x[:, c], left=np.nan, right=np.nan) for c in range(x.shape[1])])
        for key, (s, x, _) in kept.items()
    }
    return grid - start, signals, {key: unit for key, (_, _, unit) in kept.items()}, np.zeros(len(grid), bool)
