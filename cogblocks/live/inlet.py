"""LSLInlet: a Lab Streaming Layer stream (a motion-capture system's markers) resampled onto the diagram's step."""

from __future__ import annotations

import math
import socket
from typing import Any

import numpy as np
import pylsl

from cogblocks.sim import Block
from cogblocks.sim.params import finite_number, flag, one_of, shape_arg, unit_arg, wrapped_arg

__all__ = ["LSLInlet", "stream_name_arg"]

_TWO_PI = 2.0 * np.pi
# ticks between two refreshes of the clock offset (liblsl re-measures it in the background)
_CORRECTION_EVERY = 50
# a tick this far from its nominal time starts a new interpolation grid
_REGRID_S = 0.25


def stream_name_arg(owner: str, what: str, value: Any, optional: bool = False) -> str | None:
    """Return a stream name, type or id, or raise ``ValueError`` (quotes would break LSL's queries)."""
    if value is None and optional:
        return None
    if not isinstance(value, str) or not value or "'" in value:
        raise ValueError(f"{owner}: {what} must be a non-empty string without quotes, got {value!r}")
    return value


def _channel_units(info: pylsl.StreamInfo) -> list[str]:
    """The ``unit`` of each channel that the stream's description declares ('' where it declares none)."""
    units = []
    channel = info.desc().child("channels").child("channel")
    while not channel.empty():
        units.append(channel.child_value("unit"))
        channel = channel.next_sibling("channel")
    return units


class LSLInlet(Block):
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
        Unit of the samples. Channels whose description declares a unit must declare this one.
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
        Keep every received sample with its corrected timestamp (see :meth:`raw`).

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
        ``shape`` and ``unit``.
    """

    def __init__(
        self,
        name: str | None = None,
        *,
        stream_type: str | None = None,
        shape: tuple[int, ...] | int = (),
        unit: str = "1",
        wrapped: bool = False,
        mode: str = "latest",
        lag: float = 0.02,
        hold: float = 0.05,
        timeout: float = 5.0,
        record: bool = False,
        period: float | None = None,
    ) -> None:
        super().__init__(period=period)
        owner = type(self).__name__
        self.stream_name = stream_name_arg(owner, "name", name, optional=True)
        self.stream_type = stream_name_arg(owner, "stream_type", stream_type, optional=True)
        if name is None and stream_type is None:
            raise ValueError(f"{owner}: give the stream's name, its stream_type or both")
        self.shape = shape_arg(self, "shape", shape)
        self.channels = math.prod(self.shape)
        if self.channels == 0:
            raise ValueError(f"{owner}: shape must hold at least one channel, got {shape!r}")
        self.unit = unit_arg(self, "unit", unit)
        self.wrapped = wrapped_arg(self, "wrapped", wrapped)
        self.mode = one_of(self, "mode", mode, ("latest", "interpolate"))
        self.lag = finite_number(self, "lag", lag, low=0.0)
        self.hold = finite_number(self, "hold", hold, low=0.0, low_open=True)
        self.timeout = finite_number(self, "timeout", timeout, low=0.0, low_open=True)
        self.record = flag(self, "record", record)
        self.add_output(
            "y", shape=self.shape, unit=self.unit, wrapped=self.wrapped, initial=np.full(self.shape, np.nan)
        )
        self.add_output("age_ms", unit="ms", initial=np.inf)
        self.add_output("fresh", dtype=bool)
        self.inlet: pylsl.StreamInlet | None = None
        self.samples_in = 0
        self.tick_time = math.nan
        self.sample_time = math.nan
        self._grid = (math.nan, 0)  # (LSL time, base tick) of the interpolation grid's origin
        # the last `capacity` samples, oldest first: enough to interpolate `lag` back
        self._capacity = 8
        self._ts = np.empty(0)
        self._x = np.empty((0, self.channels))
        self._count = 0
        self._ticks = 0
        self._correction = 0.0
        self._remote = False
        self._log: list[tuple[np.ndarray, np.ndarray]] = []

    def describe(self) -> str:
        """The stream asked for, as said in messages (``name 'Arm' type 'MoCap'``)."""
        parts = []
        if self.stream_name is not None:
            parts.append(f"name {self.stream_name!r}")
        if self.stream_type is not None:
            parts.append(f"type {self.stream_type!r}")
        return " and ".join(parts)

    def setup(self) -> None:
        self._capacity = max(8, math.ceil(2 * (self.lag + self.hold) / self.dt) + 4)
        self._ts = np.full(self._capacity, -np.inf)
        self._x = np.full((self._capacity, self.channels), np.nan)
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
        self._check_stream(info)
        inlet.open_stream(self.timeout)
        # a stream of this machine runs on this clock; another host's is measured (about 0.6 s the first time)
        self._remote = info.hostname() != socket.gethostname()
        self._correction = 0.0
        if self._remote:
            try:
                self._correction = inlet.time_correction(self.timeout)
            except pylsl.util.TimeoutError:
                pass  # a peer that answers no clock queries: take its clock as ours
        self.inlet = inlet

    def _check_stream(self, info: pylsl.StreamInfo) -> None:
        stream = f"LSL stream {info.name()!r} (type {info.type()!r})"
        if info.channel_count() != self.channels:
            raise self._fail(
                f"{stream} has {info.channel_count()} channel(s), the port expects shape {self.shape} "
                f"= {self.channels} channel(s)"
            )
        if info.channel_format() in (pylsl.cf_string, pylsl.cf_undefined):
            raise self._fail(f"{stream} carries strings; the port expects numbers")
        declared = {u for u in _channel_units(info) if u}
        if declared - {self.unit}:
            raise self._fail(f"{stream} declares unit(s) {sorted(declared)}, the port expects {self.unit!r}")

    def reset(self) -> None:
        super().reset()
        self._grid = (math.nan, 0)
        self._ts[:] = -np.inf
        self._x[:] = np.nan
        self._count = 0

    def close(self) -> None:
        """Close the stream (the block cannot run afterwards)."""
        if self.inlet is not None:
            self.inlet.close_stream()
            self.inlet = None

    def raw(self) -> tuple[np.ndarray, np.ndarray]:
        """Every sample received with ``record=True``: timestamps on this machine's clock, and values.

        Returns
        -------
        t : numpy.ndarray, shape (n,)
        x : numpy.ndarray, shape (n, *shape)
        """
        if not self._log:
            return np.empty(0), np.empty((0, *self.shape))
        t = np.concatenate([c[0] for c in self._log])
        x = np.concatenate([c[1] for c in self._log]).reshape(len(t), *self.shape)
        return t, x

    def _pull(self) -> int:
        """Move every waiting sample into the buffer; return how many arrived."""
        if self._remote and self._ticks % _CORRECTION_EVERY == 0:
            try:
                self._correction = self.inlet.time_correction(0.0)
            except pylsl.util.TimeoutError:
                pass  # keep the last offset
        self._ticks += 1
        arrived = 0
        while True:
            samples, stamps = self.inlet.pull_chunk(timeout=0.0, max_samples=self._capacity)
            if not stamps:
                return arrived
            x = np.asarray(samples, dtype=np.float64).reshape(len(stamps), self.channels)
            x[~np.isfinite(x)] = np.nan
            t = np.asarray(stamps, dtype=np.float64) + self._correction
            if self.record:
                self._log.append((t, x.copy()))
            self.samples_in += len(t)  # next to the log, so that a Ctrl-C leaves the two in step
            m = min(len(t), self._capacity)
            self._ts[:-m] = self._ts[m:]
            self._x[:-m] = self._x[m:]
            self._ts[-m:] = t[-m:]
            self._x[-m:] = x[-m:]
            arrived += len(t)
            self._count = min(self._count + len(t), self._capacity)

    def output(self, k: int) -> None:
        if self.inlet is None:
            raise self._fail("the stream is closed")
        started = pylsl.local_clock()  # the grid's clock: a pull held up on a busy machine does not shift it
        arrived = self._pull()
        now = pylsl.local_clock()
        self.tick_time = now
        self.fresh.value[...] = arrived > 0
        if self.mode == "latest":
            at = self._ts[-1] if self._count else math.nan
            value = self._x[-1] if self._count and now - at <= self.hold else np.nan
        else:
            at = self._nominal(k, started) - self.lag
            value = self._interpolate(at) if self._count else np.nan
        self.sample_time = at
        self.age_ms.value[...] = 1e3 * (now - at) if self._count else np.inf
        self.y.value.flat[:] = value  # a sample, or a NaN for every channel

    def _nominal(self, k: int, now: float) -> float:
        """The nominal LSL time of base tick ``k``: on a grid of base steps started at a tick."""
        origin, k0 = self._grid
        step = self.dt / self.every
        nominal = origin + (k - k0) * step
        if not abs(now - nominal) <= _REGRID_S:  # the first tick, or a run paused or far behind
            self._grid = (now, k)
            nominal = now
        return nominal

    def _interpolate(self, at: float) -> np.ndarray | float:
        ts, xs = self._ts[-self._count :], self._x[-self._count :]
        if at >= ts[-1]:
            return xs[-1] if at - ts[-1] <= self.hold else np.nan
        i = int(np.searchsorted(ts, at, side="right")) - 1
        if i < 0:
            return np.nan  # before the first sample still in the buffer
        t0, t1 = ts[i], ts[i + 1]
        if t1 - t0 > self.hold:
            return np.nan
        a, b = xs[i], xs[i + 1]
        frac = (at - t0) / (t1 - t0) if t1 > t0 else 1.0
        if not self.wrapped:
            return a + frac * (b - a)
        step = np.mod(b - a + np.pi, _TWO_PI) - np.pi
        return np.mod(a + frac * step, _TWO_PI)
