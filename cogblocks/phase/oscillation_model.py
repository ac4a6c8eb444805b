"""The oscillation Algorithm 1 believes in: its centring window, frequency, the filters' lag, and its course in a gap.

:class:`OscillationModel` holds the methods of :class:`~cogblocks.phase.Algorithm1Phase` that answer questions
about the oscillation its state describes (how many samples centre the position, which frequency a measured
period gives, how far the filter in front delays the phase, where the phase and the movement are during a run of
missing samples); the block's tick decides when they are asked.
"""

from __future__ import annotations

import cmath
import math

from cogblocks.blocks.angles import TWO_PI, wrap_angle

__all__ = ["OscillationModel"]


class OscillationModel:
    """Methods of :class:`~cogblocks.phase.Algorithm1Phase` (a mixin of that block) on the oscillation of its state.

    They read the block's settings and state, all declared by the block.
    """

    def _window(self, n_pushed: int) -> int:
        """Number of samples in the centring window."""
        n = n_pushed
        if self.omega > 0.0:
            n = min(n, round(self.centre_periods * TWO_PI / (self.omega * self.dt)))
        return max(1, min(n, self._size - 1))

    def _extrapolate(self, anchor: float, ticks: int) -> float:
        """The phase ``ticks`` steps after ``anchor`` at the estimated frequency, held after ``max_coast`` periods."""
        if self.omega <= 0.0:
            return anchor
        limit = self.max_coast * TWO_PI / (self.omega * self.dt)
        return wrap_angle(anchor + self.omega * self.dt * min(ticks, limit))

    def _fill_gap(self, phase: float) -> tuple | None:
        """With ``remove_transient``, the filtered movement at a missing sample, so differences and centring go on.

        The filter in front ran on the last finite sample; its output plus its response to what it missed is
        the filtered movement as far as the extrapolation is right. Returns ``(gap_z, p, pc, v, n_pushed,
        total)`` for :meth:`update`, or None without the removal (nothing advances).
        """
        pf = float(self.p.value)
        if self._transient is None or not self.primed or not math.isfinite(pf):
            return None
        response, gap_z = self._transient.step(self.gap_z, self._movement(phase) - self.raw_prev)
        pf += response
        n_pushed, total = self.n_pushed + 1, self.total + self._movement(phase - self.lead)
        return gap_z, pf, self._centred(pf, n_pushed, total), (pf - self.p_prev) / self.dt, n_pushed, total

    def _centred(self, pf: float, n_pushed: int, total: float) -> float:
        """``pf`` minus the mean of the centring window ending at sample ``n_pushed`` (running sum ``total``)."""
        n = self._window(n_pushed)
        start = n_pushed - n
        # the slot of ``start`` is overwritten only in update(), after this read
        return pf - (total - (self.csum[start % self._size] if start else 0.0)) / n

    def _movement(self, phase: float) -> float:
        """The position the oscillation of the last measured centre and amplitudes has at ``phase``."""
        c = math.cos(phase) if self.omega > 0.0 else 0.0
        return self.p_prev - self.pc_prev + (self.amp[0] if c >= 0.0 else self.amp[1]) * c

    def _frequency(self, interval: float, omega: float) -> float:
        """The angular frequency once a period of ``interval`` seconds (0 = none) was measured."""
        if 0.0 < interval <= self.max_period:
            return TWO_PI / interval
        return omega

    def _lag(self, omega: float) -> float:
        """Phase lag in rad of the filter in front and of the backward-difference velocity at ``omega``."""
        if self._sos is None:
            return 0.0
        z = cmath.exp(-1j * omega * self.dt)
        h = 1.0 + 0j
        for b0, b1, b2, _, a1, a2 in self._sos:
            h *= (b0 + z * (b1 + z * b2)) / (1.0 + z * (a1 + z * a2))
        # the velocity lags the position by half a step; it weighs half in the phase on average
        return -cmath.phase(h) + 0.25 * omega * self.dt
