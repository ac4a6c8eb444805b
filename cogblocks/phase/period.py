"""Period estimation of a 3D cyclic motion (section 6): segment matching, then wraps of the estimate."""

from __future__ import annotations

import math

import numpy as np

from cogblocks.blocks.samples import plausible
from cogblocks.blocks.specs import COUNT, FLAG, PHASE, POSITION
from cogblocks.sim import Block
from cogblocks.sim.params import finite_number, positive_int

__all__ = ["PeriodEstimator"]

# Stages of the period estimator.
_WAITING = 0  # the hand has not moved yet
_FIRST = 1  # recording the first period, looking for the end of it by segment matching
_SYNCED = 2  # recording a later period, which ends when the estimated phase wraps
_RESYNC = 3  # a later period overflowed the buffer: wait for the next wrap to start afresh


class PeriodEstimator(Block):
    """Estimator of the last completed period of a quasi-periodic 3D motion (section 6.1.2 a).

    *Start.* Recording starts at the first sample ``p(k)`` whose speed
    ``‖p(k) − p(k−1)‖ / dt`` exceeds ``start_speed``; the sample before it, where the motion began,
    is the first one recorded (``k_P1 = k − 1``).

    *First period.* With the first segment ``a = k_P1 … k_P1 + h − 1`` and the latest one
    ``b = k − h + 1 … k``, the segment distance is the mean position mismatch plus the mean mismatch
    of the steps inside the segments::

        d(k) = 1/h Σ_{j=0}^{h−1} ‖p(a_j) − p(b_j)‖ + 1/(h−1) Σ_{j=1}^{h−1} ‖Δp(a_j) − Δp(b_j)‖,

    with ``Δp(i) = p(i) − p(i−1)``, evaluated for ``k > k_P1 + h``. The steps tell a forward pass
    from a backward one through the same place. The first ``k*`` with ``d(k*) < d(k)`` for
    ``k = k* ± 1, k* ± 2`` ends the first period at ``k_P2 = k* − (h − 1)``; it is found two
    samples after ``k*``. A local minimum counts only when ``d(k*) < match_ratio · max d`` so far:
    noise makes shallow local minima on the way up, a real repetition is a deep one.

    *Later periods* end when the estimated phase (inputs ``theta`` and ``valid``, fed back from the
    phase computer) wraps past 2π: a drop of more than π between two valid samples. The sample with
    the dropped phase is the first of the new period. A wrap that comes before ``min_period_fraction``
    of the last period's length (or before ``2 h`` samples) is estimation jitter around 2π and is
    ignored.

    Ports
    -----
    p : input, shape (3,), mm, not feedthrough
        Position.
    theta : input, rad, not feedthrough, default 0
        Estimated phase of the same tick.
    valid : input, bool, not feedthrough, default False
        Whether ``theta`` is an estimate. Left unconnected, only the first period is estimated.
    last_period : output, shape (capacity, 3), mm
        The last completed period in its first ``last_length`` rows (zeros after them).
    last_length : output, int64
        Its number of samples ``M_ℓ`` (0 before the first period completes).
    period_count : output, int64
        Number of periods completed so far; it changes exactly when ``last_period`` does.

    Parameters
    ----------
    h : int
        Segment length in samples (>= 2; 10 in the deliverable).
    capacity : int
        Longest period in samples that can be recorded (>= 2 h + 3).
    start_speed : float
        Speed in mm/s above which the motion has started (>= 0).
    match_ratio : float
        Depth a local minimum of ``d`` must have, relative to its largest value so far, in (0, 1].
    min_period_fraction : float
        Shortest later period, as a share of the last one, in [0, 1).

    Notes
    -----
    A period is stored when it completes; the outputs show it from the next tick. If the buffer
    fills before the first period is found, the search restarts from the next fast sample; if it
    fills during a later period, that period is dropped and recording starts again at the next
    wrap. Bad data policy: a sample with a non-finite or implausible (beyond 1 km) coordinate is skipped.
    """

    def __init__(
        self,
        *,
        h: int = 10,
        capacity: int = 1000,
        start_speed: float = 50.0,
        match_ratio: float = 0.3,
        min_period_fraction: float = 0.7,
        period: float | None = None,
    ) -> None:
        super().__init__(period=period)
        self.h = positive_int(self, "h", h, minimum=2)
        self.capacity = positive_int(self, "capacity", capacity, minimum=2 * self.h + 3)
        self.start_speed = finite_number(self, "start_speed", start_speed, low=0.0)
        self.match_ratio = finite_number(self, "match_ratio", match_ratio, low=0.0, high=1.0, low_open=True)
        self.min_period_fraction = finite_number(
            self, "min_period_fraction", min_period_fraction, low=0.0, high=1.0, high_open=True
        )
        cap = self.capacity
        self.add_input("p", POSITION, feedthrough=False)
        self.add_input("theta", PHASE, default=0.0, feedthrough=False)
        self.add_input("valid", FLAG, default=False, feedthrough=False)
        self.add_output("last_period", shape=(cap, 3), unit="mm")
        self.add_output("last_length", COUNT)
        self.add_output("period_count", COUNT)
        self.add_state("stage", _WAITING)
        self.add_state("previous", np.zeros(3))
        self.add_state("has_previous", False)
        self.add_state("recording", np.zeros((cap, 3)))
        self.add_state("n", 0)
        self.add_state("d_recent", np.zeros(5))  # d(k-4) ... d(k)
        self.add_state("n_d", 0)
        self.add_state("d_max", 0.0)
        self.add_state("theta_previous", 0.0)
        self.add_state("theta_previous_valid", False)
        self.add_state("stored", np.zeros((cap, 3)))
        self.add_state("stored_length", 0)
        self.add_state("stored_count", 0)

    def output(self, k: int) -> None:
        # the period output is large: copy it only when a new one has completed
        if self.period_count.value != self.stored_count:
            self.last_period.value[...] = self.stored
            self.last_length.value[...] = self.stored_length
            self.period_count.value[...] = self.stored_count

    def update(self, k: int) -> None:
        p = self.p.value
        if not plausible(p):
            return
        if self.stage == _WAITING:
            self._wait_for_motion(p)
        elif self.stage == _FIRST:
            self._first_period(p)
        else:
            self._later_period(p)

    def _wait_for_motion(self, p: np.ndarray) -> None:
        if self.has_previous and math.dist(p, self.previous) > self.start_speed * self.dt:
            self.recording[0] = self.previous
            self.recording[1] = p
            self.n = 2
            self.n_d = 0
            self.d_max = 0.0
            self.stage = _FIRST
        self.previous[...] = p
        self.has_previous = True

    def _first_period(self, p: np.ndarray) -> None:
        if self.n == self.capacity:
            self.stage = _WAITING
            self.previous[...] = p
            return
        rec, h = self.recording, self.h
        rec[self.n] = p
        self.n += 1
        newest = self.n - 1
        if newest <= h:
            return
        first = rec[:h]
        latest = rec[newest - h + 1 : newest + 1]
        d = np.linalg.norm(first - latest, axis=1).mean()
        d += np.linalg.norm(np.diff(first, axis=0) - np.diff(latest, axis=0), axis=1).mean()
        recent = self.d_recent
        recent[:-1] = recent[1:]
        recent[-1] = d
        self.n_d += 1
        self.d_max = max(self.d_max, d)
        centre = recent[2]
        if (
            self.n_d >= 5
            and centre < self.match_ratio * self.d_max
            and centre < recent[0]
            and centre < recent[1]
            and centre < recent[3]
            and centre < recent[4]
        ):
            start = newest - 2 - (h - 1)  # k_P2 - k_P1
            self._store(start)
            rest = self.n - start
            rec[:rest] = rec[start : self.n].copy()
            self.n = rest
            self.stage = _SYNCED

    def _later_period(self, p: np.ndarray) -> None:
        valid = bool(self.valid.value)
        theta = float(self.theta.value)
        wrapped = valid and self.theta_previous_valid and self.theta_previous - theta > math.pi
        self.theta_previous = theta
        self.theta_previous_valid = valid
        if wrapped:
            if self.stage == _RESYNC:
                self.n = 0
                self.stage = _SYNCED
            elif self.n >= max(2 * self.h, self.min_period_fraction * self.stored_length):
                self._store(self.n)
                self.n = 0
        if self.stage == _RESYNC:
            return
        if self.n == self.capacity:
            self.stage = _RESYNC
            return
        self.recording[self.n] = p
        self.n += 1

    def _store(self, length: int) -> None:
        self.stored[:length] = self.recording[:length]
        self.stored[length:] = 0.0
        self.stored_length = length
        self.stored_count += 1
