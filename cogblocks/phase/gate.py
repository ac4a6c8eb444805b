"""A gate in front of the 1D phase estimator: lets through samples, turns spikes and absurd values into NaN."""

from __future__ import annotations

import math

import numpy as np

from cogblocks.sim import Block
from cogblocks.sim.params import finite_number

__all__ = ["SpikeGate"]

#: Magnitude beyond which a sample is a corrupted number rather than a measurement in any unit: its square,
#: or a sum of a few hundred such samples, would overflow a float64 (1e308).
NUMERIC_LIMIT = 1e150


class SpikeGate(Block):
    """Pass a scalar sample on, or NaN when it is a spike: relative to the signal's own running scale.

    The gate keeps a running centre ``c`` and a running scale ``s`` (mean absolute deviation from
    ``c``), both exponential averages with the time constant ``memory`` in seconds (a weight
    ``1 − exp(−dt / memory)`` per sample, so they mean the same at every rate; plain means until
    that many samples were seen). A sample is a spike
    when ``|x − c| > factor · s``; for a sinusoid ``s`` is ``2/π`` of its amplitude, so the default
    ``factor = 5`` rejects what lies beyond about 3.2 amplitudes from the centre. No sample is
    rejected during the first ``memory / 2`` seconds (at least 2 samples), while ``s`` forms; and a
    rejection that lasts longer than ``memory / 4`` seconds (at least 2 samples) is a real jump,
    not a spike: the gate restarts from the sample. Only units of the signal enter (no absolute
    threshold), so the gate works the same in mm, m or sensor counts.

    Ports
    -----
    u : input, scalar, ``unit``
    y : output, scalar, ``unit``: ``u``, or NaN for a rejected sample.

    Parameters
    ----------
    factor : float
        Rejection threshold in running scales (> 0).
    memory : float
        Time constant of the running centre and scale, in seconds (> 0).
    unit : str
        Unit of the samples.

    Notes
    -----
    Bad data policy: a NaN or inf sample, and one beyond 1e150 in magnitude (no unit makes that a
    measurement; its square would overflow), gives NaN and changes no state; a spike gives NaN and
    changes no state but the count of consecutive rejections.
    """

    def __init__(
        self, *, factor: float = 5.0, memory: float = 2.0, unit: str = "mm", period: float | None = None
    ) -> None:
        super().__init__(period=period)
        self.factor = finite_number(self, "factor", factor, low=0.0, low_open=True)
        self.memory = finite_number(self, "memory", memory, low=0.0, low_open=True)
        self.add_input("u", shape=(), unit=unit)
        self.add_output("y", shape=(), unit=unit)
        self.add_state("n", 0)  # samples accepted
        self.add_state("centre", 0.0)
        self.add_state("scale", 0.0)
        self.add_state("rejected", 0)  # consecutive spikes
        self.add_scratch("_next", None)  # what output() decided, committed by update()

    def setup(self) -> None:
        self._alpha = -math.expm1(-self.dt / self.memory)
        self._warmup = max(2, math.ceil(0.5 * self.memory / self.dt))
        self._max_rejected = max(2, math.ceil(0.25 * self.memory / self.dt))

    def output(self, k: int) -> None:
        x = float(self.u.value)
        self._next = None
        if not (math.isfinite(x) and abs(x) < NUMERIC_LIMIT):
            self.y.value[...] = np.nan
            return
        n, c, s = self.n, self.centre, self.scale
        if n >= self._warmup and abs(x - c) > self.factor * s:
            if self.rejected + 1 < self._max_rejected:
                self.y.value[...] = np.nan
                self._next = (n, c, s, self.rejected + 1)
                return
            n, c, s = 0, x, s  # a jump that stays: restart the centre from here, keep the scale
        if n == 0:
            c = x
        else:
            w = max(self._alpha, 1.0 / (n + 1))  # a plain mean until the memory is filled
            c += w * (x - c)
            s += w * (abs(x - c) - s)
        self.y.value[...] = x
        self._next = (n + 1, c, s, 0)

    def update(self, k: int) -> None:
        if self._next is not None:
            self.n, self.centre, self.scale, self.rejected = self._next
