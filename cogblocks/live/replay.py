"""Replay a recorded session: the same diagram, offline, on the samples and tick clocks a live run recorded."""

from __future__ import annotations

import json
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cogblocks.live.runner import RealtimeReport, _trace
from cogblocks.live.session import RUN_STREAM
from cogblocks.live.timed import StreamHeader, TimedInlet
from cogblocks.sim import Diagram
from cogblocks.sim.timing import BASE_STEP

__all__ = ["NotASession", "RecordedStream", "Session", "load_session", "replay_session"]


class NotASession(ValueError):
    """An XDF file that pyxdf reads but no ``cogblocks live --record`` wrote (a LabRecorder file)."""


def _desc(stream: dict[str, Any]) -> dict[str, Any]:
    desc = stream["info"].get("desc") or [None]
    return desc[0] or {}


def _cogblocks(stream: dict[str, Any]) -> dict[str, str]:
    extra = _desc(stream).get("cogblocks") or [None]
    return {key: values[0] for key, values in (extra[0] or {}).items()}


def _channels(stream: dict[str, Any], key: str) -> list[str]:
    channels = (_desc(stream).get("channels") or [{}])[0] or {}
    return [(c.get(key) or [""])[0] or "" for c in channels.get("channel", [])]


def _header(stream: dict[str, Any]) -> StreamHeader:
    info = stream["info"]

    def one(key: str, default: str = "") -> str:
        return (info.get(key) or [default])[0] or default

    return StreamHeader(
        name=one("name"),
        type=one("type"),
        channel_count=int(one("channel_count", "0")),
        channel_format=one("channel_format", "double64"),
        nominal_srate=float(one("nominal_srate", "0")),
        source_id=one("source_id"),
        labels=_channels(stream, "label"),
        units=_channels(stream, "unit"),
        hostname=one("hostname"),
    )


@dataclass
class RecordedStream:
    """An inlet's recorded stream with its tick clocks: :meth:`tick` gives what the live tick had.

    Attributes
    ----------
    header : StreamHeader
    stamps, values : numpy.ndarray
        The samples as received (sender's clock, stream's unit).
    ticks : numpy.ndarray, shape (n, 4)
        Per tick: start, end (tick clock), samples received, the clock correction added to their stamps.
    """

    header: StreamHeader
    stamps: np.ndarray
    values: np.ndarray
    ticks: np.ndarray

    def __post_init__(self) -> None:
        self.rewind()

    def rewind(self) -> None:
        """Play from the first tick again."""
        self._tick = self._sample = 0

    def tick(self) -> tuple[float, float, list[tuple[np.ndarray, np.ndarray]], float]:
        """The next tick's start and end, the samples it received, and the clock correction in force."""
        if self._tick >= len(self.ticks):
            raise IndexError(f"the recording of stream {self.header.name!r} holds {len(self.ticks)} ticks only")
        started, now, arrived, correction = self.ticks[self._tick]
        self._tick += 1
        n = int(arrived)
        chunk = (self.stamps[self._sample : self._sample + n], self.values[self._sample : self._sample + n])
        self._sample += n
        return float(started), float(now), [chunk] if n else [], float(correction)


@dataclass
class Session:
    """A recorded session file, as pyxdf read it.

    Attributes
    ----------
    path : Path
    streams : list of dict
        pyxdf's streams (time stamps as recorded, not synchronised).
    dt : float
        The run's step.
    options : dict
        What built the diagram (the command line's diagram and options).
    """

    path: Path
    streams: list[dict[str, Any]]
    dt: float
    options: dict[str, Any]

    def _find(self, role: str, block: str) -> dict[str, Any] | None:
        for stream in self.streams:
            meta = _cogblocks(stream)
            if meta.get("role") == role and meta.get("block") == block:
                return stream
        return None

    def ticks(self) -> int:
        """Ticks the recorded run ran."""
        return len(self._run()["time_stamps"])

    def _run(self) -> dict[str, Any]:
        return next(s for s in self.streams if s["info"]["name"][0] == RUN_STREAM)

    def run_figures(self) -> dict[str, np.ndarray]:
        """Per tick of the recorded run: ``tick_ms``, ``start_ms``, ``late``."""
        x = np.asarray(self._run()["time_series"], dtype=np.float64).reshape(-1, 3)
        return {"tick_ms": x[:, 0], "start_ms": x[:, 1], "late": x[:, 2] > 0}

    def source(self, path: str) -> RecordedStream:
        """The recorded stream of the inlet block at ``path``; ``ValueError`` naming the file if absent."""
        stream, ticks = self._find("inlet", path), self._find("ticks", path)
        if stream is None or ticks is None:
            there = sorted(_cogblocks(s).get("block", "") for s in self.streams if _cogblocks(s).get("role") == "inlet")
            raise ValueError(f"{self.path}: no recorded inlet {path!r} (the file records inlets {there})")
        header = _header(stream)
        x = stream["time_series"]
        x = np.asarray(x, dtype=np.float64).reshape(len(stream["time_stamps"]), header.channel_count)
        return RecordedStream(
            header,
            np.asarray(stream["time_stamps"], dtype=np.float64),
            x,
            np.asarray(ticks["time_series"], dtype=np.float64).reshape(-1, 4),
        )


def load_session(path: str | os.PathLike) -> Session:
    """Read a session file written by ``cogblocks live --record``; ``ValueError`` naming the file otherwise."""
    import pyxdf

    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: no such file")
    try:
        streams, _ = pyxdf.load_xdf(str(path), synchronize_clocks=False, dejitter_timestamps=False)
    except Exception as exc:  # pyxdf raises what its parser meets: struct, XML and value errors
        raise ValueError(f"{path}: not a readable XDF file ({type(exc).__name__}: {exc})") from None
    run = [s for s in streams if s["info"]["name"][0] == RUN_STREAM]
    if not run:
        raise NotASession(f"{path}: not a cogblocks session (no {RUN_STREAM!r} stream; record with --record)")
    meta = _cogblocks(run[0])
    return Session(path, streams, float(meta.get("dt", BASE_STEP)), json.loads(meta.get("options") or "{}"))


def replay_session(diagram: Diagram, session: Session, *, record: bool = True) -> RealtimeReport:
    """Run ``diagram`` (built as the recorded run's was) on ``session``, tick for tick, as fast as it computes.

    Every inlet plays its recorded stream and tick clocks, so it computes the values the live inlet
    computed; every :class:`~cogblocks.live.LSLOutlet` publishes nothing. The report's ``tick_ms`` are the
    replay's own computation times; ``late_ticks`` are the recorded run's.
    """
    from cogblocks.live.outlet import LSLOutlet

    inlets = {path: b for path, b in diagram.blocks.items() if isinstance(b, TimedInlet)}
    for path, block in inlets.items():
        block.replay_from(session.source(path))
    for block in diagram.blocks.values():
        if isinstance(block, LSLOutlet):
            block.offline = True
    compiled = diagram.compile(session.dt)
    # a run killed mid-write may have recorded a tick's figures without its last clocks: the ticks all hold
    n = min([session.ticks(), *(len(b._source.ticks) for b in inlets.values())])
    blocks = list(compiled.blocks.values())
    ages = [b.age_ms.value for b in inlets.values()]
    tick_s = np.zeros(n)
    rows, max_age = [], -np.inf
    for i in range(n):
        began = time.perf_counter()
        out = compiled.step()
        tick_s[i] = time.perf_counter() - began
        for age in ages:
            if np.isfinite(age) and age > max_age:
                max_age = float(age)
        if record:
            rows.append(out)
    figures = {key: value[:n] for key, value in session.run_figures().items()}
    return RealtimeReport(
        ticks=n,
        late_ticks=int(figures["late"].sum()),
        overruns=int((figures["tick_ms"] > 1e3 * session.dt).sum()),
        tick_ms=1e3 * tick_s,
        start_ms=np.zeros(n),
        samples_in=sum(int(getattr(b, "samples_in", 0)) for b in blocks),
        samples_out=sum(int(getattr(b, "samples_out", 0)) for b in blocks),
        max_age_ms=max_age if math.isfinite(max_age) else math.nan,
        trace=_trace(rows, compiled, 0) if record else None,
    )
