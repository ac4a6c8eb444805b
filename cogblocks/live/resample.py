"""The inlets' resampling: irregular, time-stamped samples in, one value per tick out (live and replayed)."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["REGRID_S", "Resampler"]

_TWO_PI = 2.0 * np.pi
#: A tick this far (s) from its nominal time starts a new interpolation grid.
REGRID_S = 0.25


class Resampler:
    """Keep the newest samples of a stream and give its value at a tick (latest, or interpolated on a grid).

    This is the whole value policy of the inlets (:class:`~cogblocks.live.LSLInlet`,
    :class:`~cogblocks.live.OSCReceiver`) and of a replayed session: the same samples with the same
    tick clocks give the same values, bit for bit.

    Parameters
    ----------
    channels : int
        Values per sample.
    mode : {"latest", "interpolate"}
        ``latest``: the newest sample, NaN when older than ``hold``. ``interpolate``: the stream ``lag``
        seconds before the tick's nominal time, linear between the two samples around it (along the
        shorter arc when ``wrapped``), NaN across a gap longer than ``hold``; past the newest sample the
        newest holds for ``hold``.
    lag, hold : float
        Seconds (see ``mode``).
    wrapped : bool
        Samples are angles in ``[0, 2π)``.
    step : float
        The base step of the diagram: nominal tick times are ``origin + (k - k0) * step``.
    capacity : int
        Samples kept (enough to interpolate ``lag`` back).
    """

    def __init__(
        self, channels: int, *, mode: str, lag: float, hold: float, wrapped: bool, step: float, capacity: int
    ) -> None:
        self.channels = channels
        self.mode = mode
        self.lag = lag
        self.hold = hold
        self.wrapped = wrapped
        self.step = step
        self.capacity = max(2, capacity)
        self.ts = np.full(self.capacity, -np.inf)
        self.xs = np.full((self.capacity, channels), np.nan)
        self.count = 0
        self.grid = (math.nan, 0)  # (clock time, base tick) of the interpolation grid's origin

    def reset(self) -> None:
        """Forget every sample and the grid."""
        self.ts[:] = -np.inf
        self.xs[:] = np.nan
        self.count = 0
        self.grid = (math.nan, 0)

    def push(self, t: np.ndarray, x: np.ndarray) -> None:
        """Add samples (times ascending on the tick clock, values ``(n, channels)``; non-finite as NaN)."""
        m = min(len(t), self.capacity)
        if m == 0:
            return
        self.ts[:-m] = self.ts[m:]
        self.xs[:-m] = self.xs[m:]
        self.ts[-m:] = t[-m:]
        self.xs[-m:] = x[-m:]
        self.count = min(self.count + len(t), self.capacity)

    def read(self, k: int, started: float, now: float) -> tuple[np.ndarray | float, float]:
        """The value at base tick ``k`` begun at clock time ``started`` and read at ``now``, and the time it stands for.

        Returns ``(value, at)``: ``value`` a row of ``channels`` values or NaN; ``at`` NaN before the first sample
        in ``latest`` mode.
        """
        if self.mode == "latest":
            at = self.ts[-1] if self.count else math.nan
            value = self.xs[-1] if self.count and now - at <= self.hold else np.nan
            return value, at
        at = self._nominal(k, started) - self.lag
        return (self._interpolate(at) if self.count else np.nan), at

    def _nominal(self, k: int, now: float) -> float:
        origin, k0 = self.grid
        nominal = origin + (k - k0) * self.step
        if not abs(now - nominal) <= REGRID_S:  # the first tick, or a run paused or far behind
            self.grid = (now, k)
            nominal = now
        return nominal

    def _interpolate(self, at: float) -> np.ndarray | float:
        ts, xs = self.ts[-self.count :], self.xs[-self.count :]
        if at >= ts[-1]:
            return xs[-1] if at - ts[-1] <= self.hold else np.nan
        i = int(np.searchsorted(ts, at, side="right")) - 1
        if i < 0:
            return np.nan  # before the first sample still kept
        t0, t1 = ts[i], ts[i + 1]
        if t1 - t0 > self.hold:
            return np.nan
        a, b = xs[i], xs[i + 1]
        frac = (at - t0) / (t1 - t0) if t1 > t0 else 1.0
        if not self.wrapped:
            return a + frac * (b - a)
        step = np.mod(b - a + np.pi, _TWO_PI) - np.pi
        return np.mod(a + frac * step, _TWO_PI)
