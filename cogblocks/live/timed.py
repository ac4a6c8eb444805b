"""TimedInlet: the base of the blocks that turn a time-stamped stream into one value per tick (live or replayed)."""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any, TypedDict

import numpy as np

from cogblocks.data.units import length_factor
from cogblocks.live.resample import Resampler
from cogblocks.sim import Block
from cogblocks.sim.params import finite_number, flag, one_of, shape_arg, unit_arg, wrapped_arg

__all__ = ["InletOptions", "StreamHeader", "TimedInlet"]


@dataclass
class StreamHeader:
    """What an inlet knows of its stream: what a recording keeps in the stream's XDF header.

    ``units`` holds one entry per channel ('' where the stream declares none).
    """

    name: str
    type: str
    channel_count: int
    channel_format: str
    nominal_srate: float
    source_id: str = ""
    labels: list[str] = field(default_factory=list)
    units: list[str] = field(default_factory=list)
    hostname: str = ""


class InletOptions(TypedDict, total=False):
    """The keyword parameters every :class:`TimedInlet` takes (see :class:`~cogblocks.live.LSLInlet`)."""

    shape: tuple[int, ...] | int
    unit: str
    source_unit: str | None
    wrapped: bool
    mode: str
    lag: float
    hold: float
    record: bool
    period: float | None


class TimedInlet(Block):
    """Samples with time stamps in, one value per tick out, through a :class:`~cogblocks.live.resample.Resampler`.

    A subclass opens its stream (``_open``), hands over what arrived since the tick before
    (``_receive``: chunks of raw time stamps and values) and reads its clock (``_clock``); this base
    converts units, keeps the value policy, records what it received for a session file and, when
    :meth:`replay_from` gave it a recorded stream, takes the same samples and tick clocks from it
    instead, so that a replayed tick computes what the live tick computed.
    """

    def __init__(
        self,
        *,
        shape: tuple[int, ...] | int = (),
        unit: str = "1",
        source_unit: str | None = None,
        wrapped: bool = False,
        mode: str = "latest",
        lag: float = 0.02,
        hold: float = 0.05,
        record: bool = False,
        period: float | None = None,
    ) -> None:
        super().__init__(period=period)
        owner = type(self).__name__
        self.shape = shape_arg(self, "shape", shape)
        self.channels = math.prod(self.shape)
        if self.channels == 0:
            raise ValueError(f"{owner}: shape must hold at least one channel, got {shape!r}")
        self.unit = unit_arg(self, "unit", unit)
        self.source_unit = unit_arg(self, "source_unit", source_unit, optional=True)
        self.wrapped = wrapped_arg(self, "wrapped", wrapped)
        self.mode = one_of(self, "mode", mode, ("latest", "interpolate"))
        self.lag = finite_number(self, "lag", lag, low=0.0)
        self.hold = finite_number(self, "hold", hold, low=0.0, low_open=True)
        self.record = flag(self, "record", record)
        self.add_output(
            "y", shape=self.shape, unit=self.unit, wrapped=self.wrapped, initial=np.full(self.shape, np.nan)
        )
        self.add_output("age_ms", unit="ms", initial=np.inf)
        self.add_output("fresh", dtype=bool)
        self.samples_in = 0
        self.tick_time = math.nan
        self.sample_time = math.nan
        self.correction = 0.0  # seconds from the stream's clock to the tick clock
        self.header: StreamHeader | None = None
        self.scale = np.ones(self.channels)
        self.resampler: Resampler | None = None
        self._source: Any = None
        self._handle: Any = None  # the open stream a subclass keeps (an LSL inlet, an OSC server), for close()
        self._closed = False
        self._log: list[tuple[np.ndarray, np.ndarray]] = []  # raw stamps and raw values, as received
        self._ticks_log: list[tuple[float, float, int, float]] = []  # started, now, samples arrived, correction
        # (collection time on the stream's clock, correction) each time it changed, as LabRecorder writes them
        self._offsets_log: list[tuple[float, float]] = []

    # -- what a subclass provides ----------------------------------------------
    def _open(self) -> StreamHeader:  # pragma: no cover - abstract
        """Find and open the stream; check it (``scale = _check_stream(header)``) before opening; its header.

        What :meth:`close` must release (an inlet, a server) goes in ``_handle``, released by ``_release``.
        """
        raise NotImplementedError

    def _receive(self) -> list[tuple[np.ndarray, np.ndarray]]:  # pragma: no cover - abstract
        raise NotImplementedError

    def _clock(self) -> float:  # pragma: no cover - abstract
        raise NotImplementedError

    def _refresh_correction(self) -> None:
        """Re-measure ``correction`` if the stream runs on another clock (default: it does not)."""

    def _release(self, handle: Any) -> None:
        """Close the open stream ``handle`` (what ``_open`` kept in ``_handle``)."""

    def close(self) -> None:
        """Close the stream (the block cannot run afterwards)."""
        if self._handle is not None:
            self._release(self._handle)
            self._handle = None
        self._closed = True

    # -- replay ------------------------------------------------------------------
    def replay_from(self, source: Any) -> None:
        """Take samples and tick clocks from a recorded stream (see :mod:`cogblocks.live.replay`), before compiling."""
        self._source = source

    @property
    def replaying(self) -> bool:
        """Whether the block plays a recorded stream."""
        return self._source is not None

    # -- lifecycle ---------------------------------------------------------------
    def setup(self) -> None:
        capacity = max(8, math.ceil(2 * (self.lag + self.hold) / self.dt) + 4)
        self.resampler = Resampler(
            self.channels,
            mode=self.mode,
            lag=self.lag,
            hold=self.hold,
            wrapped=self.wrapped,
            step=self.dt / self.every,
            capacity=capacity,
        )
        if self._source is not None:
            self.header = self._source.header
            self.scale = self._check_stream(self.header)
        else:
            self.header = self._open()  # which checks the stream and sets ``scale`` before opening it
            self._closed = False

    def _check_stream(self, info: StreamHeader) -> np.ndarray:
        """The factor per channel from the stream's units to the port's, or raise naming the stream."""
        stream = f"{self._stream_kind} {info.name!r} (type {info.type!r})"
        if info.channel_count != self.channels:
            raise self._fail(
                f"{stream} has {info.channel_count} channel(s), the port expects shape {self.shape} "
                f"= {self.channels} channel(s)"
            )
        if info.channel_format in ("string", "undefined"):
            raise self._fail(f"{stream} carries strings; the port expects numbers")
        units = list(info.units) + [""] * (self.channels - len(info.units))
        if self.source_unit is not None and any(units):
            raise self._fail(
                f"{stream} declares unit(s) {sorted(set(u for u in units if u))}; source_unit "
                f"{self.source_unit!r} is for a stream that declares none"
            )
        if not any(units) and self.source_unit is None and self.unit != "1":  # a plain number cannot be misread
            warnings.warn(
                f"{self.name or type(self).__name__}: {stream} declares no unit; its values are taken as "
                f"{self.unit!r} (give the stream's unit as source_unit, --unit on the command line)",
                stacklevel=2,
            )
        factors = []
        for u in units:
            try:
                factors.append(length_factor(u or self.source_unit or self.unit, self.unit, stream))
            except ValueError as exc:
                raise self._fail(str(exc)) from None
        return np.array(factors)

    def reset(self) -> None:
        super().reset()
        if self.resampler is not None:
            self.resampler.reset()

    # -- ticks ---------------------------------------------------------------------
    def output(self, k: int) -> None:
        if self._source is not None:
            started, now, chunks, self.correction = self._source.tick()
        else:
            if not self._is_open():
                raise self._fail("the stream is closed")
            started = self._clock()  # the grid's clock: a receive held up on a busy machine does not shift it
            self._refresh_correction()
            chunks = self._receive()
            now = self._clock()
        arrived = self._take(chunks)
        if self.record:
            if not self._offsets_log or self._offsets_log[-1][1] != self.correction:
                self._offsets_log.append((started - self.correction, self.correction))
            self._ticks_log.append((started, now, arrived, self.correction))
        self.tick_time = now
        self.fresh.value[...] = arrived > 0
        value, at = self.resampler.read(k, started, now)
        self.sample_time = at
        self.age_ms.value[...] = 1e3 * (now - at) if self.resampler.count else np.inf
        self.y.value.flat[:] = value  # a sample, or a NaN for every channel

    def _is_open(self) -> bool:
        return not self._closed

    def _take(self, chunks: list[tuple[np.ndarray, np.ndarray]]) -> int:
        arrived = 0
        for stamps, values in chunks:
            if self.record:
                self._log.append((stamps, values))
            self.samples_in += len(stamps)  # next to the log, so that a Ctrl-C leaves the two in step
            x = np.asarray(values, dtype=np.float64).reshape(len(stamps), self.channels) * self.scale
            x[~np.isfinite(x)] = np.nan
            self.resampler.push(np.asarray(stamps, dtype=np.float64) + self.correction, x)
            arrived += len(stamps)
        return arrived

    # -- what was received -----------------------------------------------------------
    def raw(self) -> tuple[np.ndarray, np.ndarray]:
        """Every sample received with ``record=True``: time stamps on the tick clock, values in the port's unit.

        Returns
        -------
        t : numpy.ndarray, shape (n,)
        x : numpy.ndarray, shape (n, *shape)
        """
        stamps, values, corrections = self._received()
        x = np.asarray(values, dtype=np.float64).reshape(len(stamps), self.channels) * self.scale
        x[~np.isfinite(x)] = np.nan
        return stamps + corrections, x.reshape(len(stamps), *self.shape)

    def _received(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Raw stamps, raw values and the correction each was read with."""
        if not self._log:
            return np.empty(0), np.empty((0, self.channels)), np.empty(0)
        stamps = np.concatenate([np.asarray(c[0], dtype=np.float64) for c in self._log])
        values = np.concatenate([np.asarray(c[1]).reshape(len(c[0]), self.channels) for c in self._log])
        # the correction each tick applied, repeated for the samples that tick received
        ticks = np.array(self._ticks_log, dtype=np.float64).reshape(-1, 4)
        corrections = np.repeat(ticks[:, 3], ticks[:, 2].astype(int))
        if len(corrections) < len(stamps):  # a Ctrl-C between a receive and its tick's log entry
            corrections = np.concatenate([corrections, np.full(len(stamps) - len(corrections), self.correction)])
        return stamps, values, corrections

    def session(self) -> dict[str, Any]:
        """What a session file keeps of this inlet: header, raw samples, tick clocks and corrections, clock offsets."""
        stamps, values, _ = self._received()
        ticks = np.array(self._ticks_log, dtype=np.float64).reshape(-1, 4)
        return {"header": self.header, "stamps": stamps, "values": values, "ticks": ticks, "offsets": self._offsets_log}

    _stream_kind = "stream"
