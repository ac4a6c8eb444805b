"""Record a live run as an XDF session: every stream the run read and wrote, its tick clocks and its figures.

A session file holds, as LabRecorder would, one XDF stream per LSL stream the diagram read
(:class:`~cogblocks.live.timed.TimedInlet` blocks: the samples as received, on the sender's clock,
with the clock offsets the inlet applied) and wrote (:class:`~cogblocks.live.LSLOutlet` blocks), each
with its name, type, channel labels and units. Three kinds of cogblocks streams complete it, so that
:mod:`cogblocks.live.replay` can re-run the diagram tick for tick:

* ``<block> ticks`` (type ``cogblocks.ticks``), one per inlet: each tick's start and end on the tick
  clock, how many samples it received and the clock correction it added to their time stamps
  (channels ``started``, ``now``, ``arrived``, ``correction``);
* ``cogblocks run`` (type ``cogblocks.run``): each tick's ``tick_ms``, ``start_ms`` and ``late``, with
  the step and the run's options in its description.

Every stream names its role and block in ``<desc><cogblocks>`` (``role``, ``block``); the run stream's
footer says whether the run was interrupted.

:class:`SessionRecorder` writes the file as the run goes: the headers before the first tick, then
what came every ``every`` seconds (0.5 s), from a thread of its own, so that a run that crashes or is
killed leaves a valid file that lacks at most the last half second. :func:`write_session` writes a
finished run at once.
"""

from __future__ import annotations

import json
import os
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from cogblocks.data.xdf_write import XDFStream, XDFWriter, write_whole
from cogblocks.live.timed import TimedInlet
from cogblocks.sim import CompiledDiagram

__all__ = ["RUN_STREAM", "TICKS_TYPE", "SessionRecorder", "enable_recording", "write_session"]

#: Name of the stream with the run's per-tick figures.
RUN_STREAM = "cogblocks run"
#: Type of the inlets' tick-clock streams.
TICKS_TYPE = "cogblocks.ticks"


def _inlets(compiled: CompiledDiagram) -> dict[str, TimedInlet]:
    return {path: b for path, b in compiled.blocks.items() if isinstance(b, TimedInlet)}


def _outlets(compiled: CompiledDiagram) -> dict[str, Any]:
    from cogblocks.live.outlet import LSLOutlet

    return {path: b for path, b in compiled.blocks.items() if isinstance(b, LSLOutlet)}


def enable_recording(compiled: CompiledDiagram) -> None:
    """Make every inlet and outlet of ``compiled`` keep what it receives and sends (before the run)."""
    for block in (*_inlets(compiled).values(), *_outlets(compiled).values()):
        block.record = True


class _Layout:
    """The session's streams over the blocks' logs: declares them to a writer, then appends what is new.

    Each :meth:`append` takes the logs' lengths in the order they grow within a tick (the run's rows,
    then each inlet's ticks, then its samples), so a file cut at any flush stays consistent: no run row
    without its ticks, no tick without its samples.
    """

    def __init__(self, compiled: CompiledDiagram, options: dict[str, Any] | None, rows: list) -> None:
        self.compiled, self.options, self.rows = compiled, options or {}, rows
        self.inlets, self.outlets = _inlets(compiled), _outlets(compiled)
        self.cursors: dict[str, int] = {}
        self.index: dict[str, int] = {}

    def declare(self, writer: XDFWriter) -> None:
        """Every stream's header, in the order of the file."""
        for path, inlet in self.inlets.items():
            h = inlet.header
            self.index[f"in {path}"] = writer.add_stream(
                XDFStream(
                    h.name,
                    h.type,
                    np.empty(0),
                    np.empty((0, h.channel_count)),
                    channel_format=h.channel_format,
                    nominal_srate=h.nominal_srate,
                    labels=list(h.labels),
                    units=list(h.units),
                    source_id=h.source_id,
                    hostname=h.hostname,
                    channels=h.channel_count,
                    desc={"role": "inlet", "block": path},
                )
            )
            self.index[f"ticks {path}"] = writer.add_stream(
                XDFStream(
                    f"{path} ticks",
                    TICKS_TYPE,
                    np.empty(0),
                    np.empty((0, 4)),
                    labels=["started", "now", "arrived", "correction"],
                    units=["s", "s", "1", "s"],
                    desc={"role": "ticks", "block": path},
                    channels=4,
                )
            )
        for path, outlet in self.outlets.items():
            n = len(outlet.labels)
            self.index[f"out {path}"] = writer.add_stream(
                XDFStream(
                    outlet.stream_name,
                    outlet.stream_type,
                    np.empty(0),
                    np.empty((0, n)),
                    nominal_srate=1.0 / outlet.dt,
                    labels=list(outlet.labels),
                    units=[outlet.u.spec.unit or ""] * n,
                    source_id=outlet.source_id,
                    channels=n,
                    desc={"role": "outlet", "block": path},
                )
            )
        dt = self.compiled.dt
        self.index["run"] = writer.add_stream(
            XDFStream(
                RUN_STREAM,
                "cogblocks.run",
                np.empty(0),
                np.empty((0, 3)),
                nominal_srate=1.0 / dt,
                labels=["tick_ms", "start_ms", "late"],
                units=["ms", "ms", "1"],
                channels=3,
                desc={"role": "run", "dt": repr(dt), "options": json.dumps(self.options)},
            )
        )

    def _new(self, key: str, log: list, n: int) -> list:
        start = self.cursors.get(key, 0)
        self.cursors[key] = n
        return log[start:n]

    def _origin(self, writer: XDFWriter, key: str, stamps: np.ndarray) -> None:
        """A zero clock offset at the first sample: a stream on the recorder's own clock."""
        if len(stamps) and f"origin {key}" not in self.cursors:
            self.cursors[f"origin {key}"] = 1
            writer.offset(self.index[key], float(stamps[0]), 0.0)

    def append(self, writer: XDFWriter) -> None:
        """Append to ``writer`` what the logs gained since the last call."""
        rows = self._new("run", self.rows, len(self.rows))
        clocks = None
        for path, inlet in self.inlets.items():
            ticks = np.array(self._new(f"ticks {path}", inlet._ticks_log, len(inlet._ticks_log))).reshape(-1, 4)
            offsets = self._new(f"offsets {path}", inlet._offsets_log, len(inlet._offsets_log))
            chunks = self._new(f"in {path}", inlet._log, len(inlet._log))
            for stamps, values in chunks:
                writer.samples(self.index[f"in {path}"], stamps, np.asarray(values).reshape(len(stamps), -1))
            for time, value in offsets:
                writer.offset(self.index[f"in {path}"], time, value)
            self._origin(writer, f"ticks {path}", ticks[:, 1])
            writer.samples(self.index[f"ticks {path}"], ticks[:, 1], ticks)
            clocks = inlet._ticks_log if clocks is None else clocks
        for path, outlet in self.outlets.items():
            got = self._new(f"out {path}", outlet._log, len(outlet._log))
            stamps = np.array([stamp for stamp, _ in got], dtype=np.float64)
            self._origin(writer, f"out {path}", stamps)
            writer.samples(
                self.index[f"out {path}"], stamps, np.array([v for _, v in got]).reshape(len(got), len(outlet.labels))
            )
        if rows:
            first = self.cursors["run"] - len(rows)
            ticks = range(first, first + len(rows))
            # each tick on the first inlet's tick clock (its end), else on the step's grid
            stamps = np.array([clocks[i][1] if clocks is not None else i * self.compiled.dt for i in ticks])
            self._origin(writer, "run", stamps)
            writer.samples(self.index["run"], stamps, np.array(rows, dtype=np.float64).reshape(-1, 3))

    def write_all(self, f: BinaryIO, interrupted: bool) -> None:
        """The whole session so far, from the start, to ``f``."""
        self.cursors = {}
        writer = XDFWriter(f)
        self.declare(writer)
        self.append(writer)
        writer.finish({self.index["run"]: {"interrupted": str(bool(interrupted)).lower()}})


def _rows(report: Any, dt: float) -> list[tuple[float, float, float]]:
    """The run's per-tick figures: tick_ms, start_ms, and whether the tick finished late."""
    late = report.start_ms + report.tick_ms > 1e3 * dt
    return list(zip(report.tick_ms, report.start_ms, late.astype(float), strict=True))


def write_session(
    path: str | os.PathLike, compiled: CompiledDiagram, report: Any, options: dict[str, Any] | None = None
) -> os.PathLike:
    """Write a finished, recorded run to the XDF file ``path`` at once.

    Raises
    ------
    RecordingError
        As :func:`~cogblocks.data.xdf_write.write_xdf`: the file then went to a temporary file it names.
    """
    layout = _Layout(compiled, options, _rows(report, compiled.dt))
    return write_whole(path, lambda f: layout.write_all(f, report.interrupted))


class SessionRecorder:
    """A live run recorded to an XDF file as it goes (see the module's description).

    Create it after compiling and before the run; pass it to :func:`~cogblocks.live.run_realtime`
    (``recorder=``), which reports each tick to :meth:`ticked` and starts and closes it.

    Parameters
    ----------
    path : str or os.PathLike
        The session file (written in place: valid after every flush).
    compiled : CompiledDiagram
        The diagram that will run (its inlets' streams are open).
    options : dict, optional
        What built the diagram, kept as JSON for :mod:`~cogblocks.live.replay`.
    every : float
        Seconds between two writes (> 0).

    Raises
    ------
    OSError
        If ``path`` cannot be created.
    """

    def __init__(
        self, path: str | os.PathLike, compiled: CompiledDiagram, options: dict[str, Any] | None = None, *, every=0.5
    ) -> None:
        if not every > 0:
            raise ValueError(f"SessionRecorder: every must be a positive number of seconds, got {every!r}")
        enable_recording(compiled)
        self.path = Path(path)
        self.every = float(every)
        self.rows: list[tuple[float, float, float]] = []
        self._layout = _Layout(compiled, options, self.rows)
        self._file = open(self.path, "wb")  # held open for the whole run, closed by close()
        self._writer = XDFWriter(self._file)
        self._lock = threading.Lock()
        self._failed: OSError | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._layout.declare(self._writer)
        self.flush()

    def ticked(self, tick_ms: float, start_ms: float, late: bool) -> None:
        """One tick of the run: its computation time, how late it started, whether it finished late."""
        self.rows.append((tick_ms, start_ms, float(late)))

    def start(self) -> None:
        """Write what came every ``every`` seconds from a thread, until :meth:`close`."""
        if self._thread is None:
            self._thread = threading.Thread(target=self._loop, name="cogblocks recorder", daemon=True)
            self._thread.start()

    def _loop(self) -> None:
        while not self._stop.wait(self.every):
            self.flush()

    def flush(self) -> None:
        """Append what the run recorded since the last flush to the file, and flush it."""
        with self._lock:
            if self._failed is not None:
                return
            try:
                self._layout.append(self._writer)
                self._writer.flush()
            except OSError as exc:  # a full disk, a folder gone: the logs still hold it all
                self._failed = exc

    def close(self, interrupted: bool = False) -> Path:
        """Write the rest and the footers, and close the file; return its path.

        Raises
        ------
        RecordingError
            If the file could not be written to the end: the whole session then went to a temporary
            file it names (or nowhere, if that failed too).
        """
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
        self.flush()
        with self._lock:
            if self._failed is None:
                try:
                    self._writer.finish({self._layout.index["run"]: {"interrupted": str(bool(interrupted)).lower()}})
                    os.fsync(self._file.fileno())
                except OSError as exc:
                    self._failed = exc
            try:
                self._file.close()
            except OSError as exc:
                self._failed = self._failed or exc
        if self._failed is not None:
            fill: Callable[[BinaryIO], None] = lambda f: self._layout.write_all(f, interrupted)  # noqa: E731
            write_whole(self.path, fill, failed=self._failed)
        return self.path
