"""LSLInlet: a Lab Streaming Layer stream (a motion-capture system's markers) resampled onto the diagram's step."""

from __future__ import annotations

import math
import socket
from typing import Any, Unpack

import numpy as np
import pylsl

from cogblocks.live.timed import InletOptions, StreamHeader, TimedInlet
from cogblocks.sim.params import finite_number

__all__ = ["LSLInlet", "stream_name_arg"]

# ticks between two refreshes of the clock offset (liblsl re-measures it in the background)
_CORRECTION_EVERY = 50
_FORMATS = {
    pylsl.cf_float32: "float32",
    pylsl.cf_double64: "double64",
    pylsl.cf_string: "string",
    pylsl.cf_int32: "int32",
    pylsl.cf_int16: "int16",
    pylsl.cf_int8: "int8",
    pylsl.cf_int64: "int64",
    pylsl.cf_undefined: "undefined",
}


def stream_name_arg(owner: str, what: str, value: Any, optional: bool = False) -> str | None:
    """Return a stream name, type or id, or raise ``ValueError`` (quotes would break LSL's queries)."""
    if value is None and optional:
        return None
    if not isinstance(value, str) or not value or "'" in value:
        raise ValueError(f"{owner}: {what} must be a non-empty string without quotes, got {value!r}")
    return value


def _channels(info: pylsl.StreamInfo, key: str) -> list[str]:
    """The ``key`` (``unit``, ``label``) of each channel that the stream's description declares ('' where none)."""
    found = []
    channel = info.desc().child("channels").child("channel")
    while not channel.empty():
        found.append(channel.child_value(key))
        channel = channel.next_sibling("channel")
    return found


class LSLInlet(TimedInlet):
    """A Lab Streaming Layer stream, resampled onto the diagram's fixed step.

    The stream is resolved (by name and/or type) and opened when the diagram is compiled. Each tick
    pulls every sample that arrived since the tick before, maps its LSL timestamp onto this
    machine's clock (``time_correction``, measured when compiled and every 50 ticks for a stream of
    another host) and turns irregular arrival into one value per tick:

    * ``mode="latest"``: the newest sample;
    * ``mode="interpolate"``: the stream at ``lag`` seconds before the tick's nominal time, linearly
      interpolated between the two samples around that time (along the shorter arc for a wrapped
      angle). The nominal time of tick ``k`` is the first tick's start plus ``k`` base steps, so the
      values are the stream resampled on a regular grid however late a tick runs (a tick more than
      0.25 s off its nominal time starts a new grid). A lag of one sample period of the stream plus
      its transport delay keeps the interpolation inside received data; past the newest sample the
      newest one holds. Use this mode for blocks that differentiate or filter their input.

    Ports
    -----
    y : output, ``shape``, float64, ``unit``, ``wrapped``
        The stream's value at this tick (channels in stream order, reshaped to ``shape``).
    age_ms : output, scalar, ms
        Age of ``y``: time since the newest received sample was taken (``latest``), or since the
        time it was interpolated at (``interpolate``); ``inf`` before the first sample.
    fresh : output, scalar, bool
        Whether at least one sample arrived since the tick before.

    Parameters
    ----------
    name : str, optional
        The stream's name (``StreamInfo.name``).
    stream_type : str, optional
        The stream's content type (``"MoCap"``, ``"Phase"``, ...). Give a name, a type or both.
    shape : tuple of int
        Shape of one sample; the stream must have ``prod(shape)`` channels (``()``: one channel).
    unit : str
        Unit of the port. Channels whose description declares a unit must declare this one, or a length
        (m, cm, mm) when ``unit`` is a length: the values are converted.
    source_unit : str, optional
        The unit of a stream that declares none (without it such a stream is taken in ``unit``, with a
        warning). Refused for a stream that declares its units.
    wrapped : bool
        Whether the samples are angles wrapped to ``[0, 2π)``.
    mode : {"latest", "interpolate"}
        How a tick's value is taken from the samples (see above).
    lag : float
        Seconds before the tick's nominal time at which ``interpolate`` reads the stream (>= 0;
        unused by ``latest``).
    hold : float
        Longest time in seconds that a sample stands for: a newest sample older than ``hold``, or a
        gap between two samples longer than ``hold``, gives NaN (> 0). Ages count from the samples'
        timestamps (their capture, for a tracker that stamps them so): for a stream that arrives late,
        ``hold`` must exceed its delay.
    timeout : float
        Seconds to wait for the stream when compiled (> 0).
    record : bool
        Keep every received sample and the tick clocks (see :meth:`raw`; what a session file records).

    Attributes
    ----------
    samples_in : int
        Samples received so far.
    tick_time : float
        The LSL clock (``pylsl.local_clock()``) at the last tick.
    sample_time : float
        The LSL time that ``y`` stands for at the last tick (``tick_time`` minus the age).

    Notes
    -----
    Bad data policy: a non-finite sample (a tracker's lost marker) comes out as NaN; a tick with no
    sample recent enough (the stream stopped, a gap longer than ``hold``, before the first sample)
    gives NaN. Downstream blocks' own policies deal with the NaN (the phase estimator holds, the
    Kalman filter predicts through it). ``y`` is therefore finite or NaN, never inf.

    Raises
    ------
    TimeoutError
        When compiled, if no stream matches within ``timeout`` (the message names the stream).
    DiagramError
        When compiled, if the stream's channel count, channel format or declared units do not fit
        ``shape`` and ``unit`` (a unit that is neither ``unit`` nor, for a length port, a length).
    """

    _stream_kind = "LSL stream"

    def __init__(
        self,
        name: str | None = None,
        *,
        stream_type: str | None = None,
        timeout: float = 5.0,
        **options: Unpack[InletOptions],
    ) -> None:
        owner = type(self).__name__
        stream_name = stream_name_arg(owner, "name", name, optional=True)
        stream_type = stream_name_arg(owner, "stream_type", stream_type, optional=True)
        if name is None and stream_type is None:
            raise ValueError(f"{owner}: give the stream's name, its stream_type or both")
        super().__init__(**options)
        self.stream_name = stream_name
        self.stream_type = stream_type
        self.timeout = finite_number(self, "timeout", timeout, low=0.0, low_open=True)
        self._ticks = 0
        self._remote = False

    def describe(self) -> str:
        """The stream asked for, as said in messages (``name 'Arm' type 'MoCap'``)."""
        parts = []
        if self.stream_name is not None:
            parts.append(f"name {self.stream_name!r}")
        if self.stream_type is not None:
            parts.append(f"type {self.stream_type!r}")
        return " and ".join(parts)

    def _open(self) -> StreamHeader:
        clauses = []
        if self.stream_name is not None:
            clauses.append(f"name='{self.stream_name}'")
        if self.stream_type is not None:
            clauses.append(f"type='{self.stream_type}'")
        found = pylsl.resolve_bypred(" and ".join(clauses), minimum=1, timeout=self.timeout)
        label = self.name or type(self).__name__
        if not found:
            raise TimeoutError(
                f"{label}: no LSL stream with {self.describe()} found within {self.timeout:g} s "
                "(is the sender running, on this machine or on a peer that lsl_api.cfg reaches?)"
            )
        inlet = pylsl.StreamInlet(found[0], max_buflen=max(1, math.ceil(10 * self.hold)), recover=True)
        info = inlet.info(self.timeout)
        header = StreamHeader(
            name=info.name(),
            type=info.type(),
            channel_count=info.channel_count(),
            channel_format=_FORMATS.get(info.channel_format(), "undefined"),
            nominal_srate=info.nominal_srate(),
            source_id=info.source_id(),
            labels=_channels(info, "label"),
            units=_channels(info, "unit"),
            hostname=info.hostname(),
        )
        self.scale = self._check_stream(header)  # before opening: a stream that does not fit is refused at once
        inlet.open_stream(self.timeout)
        # a stream of this machine runs on this clock; another host's is measured (about 0.6 s the first time)
        self._remote = info.hostname() != socket.gethostname()
        self.correction = 0.0
        if self._remote:
            try:
                self.correction = inlet.time_correction(self.timeout)
            except pylsl.util.TimeoutError:
                pass  # a peer that answers no clock queries: take its clock as ours
        self._ticks = 0
        self._handle = inlet
        return header

    @property
    def inlet(self) -> pylsl.StreamInlet | None:
        """The open LSL inlet (None before compiling and once closed)."""
        return self._handle

    def _release(self, handle: pylsl.StreamInlet) -> None:
        handle.close_stream()

    def _clock(self) -> float:
        return pylsl.local_clock()

    def _refresh_correction(self) -> None:
        if self._remote and self._ticks % _CORRECTION_EVERY == 0:
            try:
                self.correction = self.inlet.time_correction(0.0)
            except pylsl.util.TimeoutError:
                pass  # keep the last offset
        self._ticks += 1

    def _receive(self) -> list[tuple[np.ndarray, np.ndarray]]:
        chunks = []
        cap = self.resampler.capacity
        while True:
            samples, stamps = self.inlet.pull_chunk(timeout=0.0, max_samples=cap)
            if not stamps:
                return chunks
            chunks.append((np.asarray(stamps, dtype=np.float64), np.asarray(samples, dtype=np.float64)))
