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

Every stream names its role and block in ``<desc><cogblocks>`` (``role``, ``block``).
"""

from __future__ import annotations

import json
import os
from typing import Any

import numpy as np

from cogblocks.live.timed import TimedInlet
from cogblocks.live.xdf import XDFStream, write_xdf
from cogblocks.sim import CompiledDiagram

__all__ = ["RUN_STREAM", "TICKS_TYPE", "enable_recording", "session_streams", "write_session"]

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


def _origin(stamps: np.ndarray) -> list[tuple[float, float]]:
    """A zero clock offset: streams on the recorder's own clock (a reader that synchronises leaves them)."""
    return [(float(stamps[0]), 0.0)] if len(stamps) else []


def session_streams(compiled: CompiledDiagram, report: Any, options: dict[str, Any] | None = None) -> list[XDFStream]:
    """The XDF streams of a recorded run (see the module's description).

    Parameters
    ----------
    compiled : CompiledDiagram
        The diagram that ran, after :func:`enable_recording` and the run.
    report : RealtimeReport
        The run's report (``tick_ms``, ``start_ms``).
    options : dict, optional
        What built the diagram (the command line's diagram name and options), kept as JSON.
    """
    streams = []
    first_ticks = None
    for path, inlet in _inlets(compiled).items():
        got = inlet.session()
        h = got["header"]
        role = {"role": "inlet", "block": path}
        streams.append(
            XDFStream(
                h.name,
                h.type,
                got["stamps"],
                got["values"],
                channel_format=h.channel_format,
                nominal_srate=h.nominal_srate,
                labels=list(h.labels),
                units=list(h.units),
                source_id=h.source_id,
                hostname=h.hostname,
                clock_offsets=list(got["offsets"]),
                desc=role,
            )
        )
        ticks = got["ticks"]
        first_ticks = ticks if first_ticks is None else first_ticks
        streams.append(
            XDFStream(
                f"{path} ticks",
                TICKS_TYPE,
                ticks[:, 1],
                ticks,
                labels=["started", "now", "arrived", "correction"],
                units=["s", "s", "1", "s"],
                clock_offsets=_origin(ticks[:, 1]),
                desc={"role": "ticks", "block": path},
            )
        )
    for path, outlet in _outlets(compiled).items():
        got = outlet.session()
        streams.append(
            XDFStream(
                outlet.stream_name,
                outlet.stream_type,
                got["stamps"],
                got["values"],
                nominal_srate=1.0 / outlet.dt,
                labels=list(outlet.labels),
                units=[outlet.u.spec.unit or ""] * len(outlet.labels),
                source_id=outlet.source_id,
                clock_offsets=_origin(got["stamps"]),
                desc={"role": "outlet", "block": path},
            )
        )
    n = len(report.tick_ms)
    period_ms = 1e3 * compiled.dt
    figures = np.column_stack([report.tick_ms, report.start_ms, report.start_ms + report.tick_ms > period_ms])
    stamps = first_ticks[:n, 1] if first_ticks is not None and len(first_ticks) >= n else compiled.dt * np.arange(n)
    streams.append(
        XDFStream(
            RUN_STREAM,
            "cogblocks.run",
            stamps,
            figures,
            nominal_srate=1.0 / compiled.dt,
            labels=["tick_ms", "start_ms", "late"],
            units=["ms", "ms", "1"],
            clock_offsets=_origin(stamps),
            desc={
                "role": "run",
                "dt": repr(compiled.dt),
                "options": json.dumps(options or {}),
                "interrupted": str(bool(report.interrupted)).lower(),
            },
        )
    )
    return streams


def write_session(
    path: str | os.PathLike, compiled: CompiledDiagram, report: Any, options: dict[str, Any] | None = None
) -> os.PathLike:
    """Write the recorded run to the XDF file ``path`` (see :func:`~cogblocks.live.xdf.write_xdf` for failures)."""
    return write_xdf(path, session_streams(compiled, report, options))
