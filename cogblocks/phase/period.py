"""Period estimation of a 3D cyclic motion (section 6): segment matching, then wraps of the estimate."""

from __future__ import annotations

import math

import numpy as np

from cogblocks.blocks.angles import TWO_PI
from cogblocks.blocks.samples import MEASURABLE, plausible
from cogblocks.blocks.specs import COUNT, FLAG, PHASE, POSITION
from cogblocks.sim import Block
from cogblocks.sim.params import finite_number, positive_int

__all__ = ["PeriodEstimator", "segment_samples"]

# Stages of the period estimator.
_WAITING = 0  # the hand has not moved yet
_FIRST = 1  # recording the first period, looking for the end of it by segment matching
_SYNCED = 2  # recording a later period, which ends when the estimated phase wraps
_RESYNC = 3  # a later period overflowed the buffer: wait for the next wrap to start afresh
# Segments of the first period whose repeat is looked for: a freeze can hide the first one's repeat.
_SEGMENTS = 5


def segment_samples(h: float, dt: float) -> int:
    """The matching segment ``h`` (s) in samples at step ``dt`` (s): rounded, never fewer than 2."""
    return max(2, round(h / dt))


class PeriodEstimator(Block):
    """Estimator of the last completed period of a quasi-periodic 3D motion (section 6.1.2 a).

    Each recorded sample comes with its phase, so that the customizer can fit the reference to the
    period by phase rather than by sample count (the phase coordinate stays tied to the motion).

    *Start.* Recording starts at the first sample ``p(k)`` whose speed
    ``‖p(k) − p(k−1)‖ / dt`` exceeds ``start_speed · σ(k−1)``, ``σ(k−1)`` the spread of the samples
    before it (the root mean square distance from their mean: the signal's own scale, so the rule is
    the same in mm, m or sensor counts); the sample before it, where the motion began, is the first
    one recorded (``k_P1 = k − 1``). A motion that starts with the recording (σ = 0) starts at its
    first moving sample; on a hand at rest the spread is the sensor noise's.

    *First period.* With ``H`` the segment ``h`` in samples (:func:`segment_samples`), the first
    segment ``a = k_P1 … k_P1 + H − 1`` and the latest one ``b = k − H + 1 … k``, the segment
    distance is the mean position mismatch plus the mean mismatch of the steps inside the segments::

        d(k) = 1/H Σ_{j=0}^{H−1} ‖p(a_j) − p(b_j)‖ + 1/(H−1) Σ_{j=1}^{H−1} ‖Δp(a_j) − Δp(b_j)‖,

    with ``Δp(i) = p(i) − p(i−1)``, evaluated for ``k > k_P1 + H``. The first ``k*`` with
    ``d(k*) < d(k)`` for ``k = k* ± 1, k* ± 2`` ends the first period at ``k_P2 = k* + δ − (H − 1)``,
    ``δ`` in ``[−½, ½]`` placing the minimum of the parabola through ``d(k* − 1 … k* + 1)``: the
    period ``M₁ = k_P2 − k_P1`` is a real number of samples. A local minimum counts only when
    ``d(k*) < match_ratio · max d`` so far: noise makes shallow local minima on the way up, a real
    repetition is a deep one. A frozen tracker can hide the repeat of the first segment, so the same
    search runs for the first five segments (``a`` shifted by ``0, H, … 4H``); the first repeat found
    ends the period (``k_P2`` shifted back by the segment's offset). On a steady recording it is
    the first segment's. The samples of the first period get the phases ``2π j / M₁``
    (phase 0 at the start of the motion, assumption 3), those recorded after it the same rate
    continued.

    *Later periods* end when the estimated phase (inputs ``theta`` and ``valid``, fed back from the
    phase computer) wraps past 2π: a drop of more than π between two valid samples. The sample with
    the dropped phase is the first of the new period; each sample is recorded with its estimated
    phase, a frozen sample (equal to the one before) is not recorded. A wrap that comes less than
    ``min_period_fraction`` of the last cycle's duration after the last crossing (or before ``2 H``
    samples) is estimation jitter around 2π and is ignored; the last cycle's duration is the last
    period's divided by the number of cycles its phases span (two after a missed wrap). The
    duration of a period is the time between the crossings of 2π, each placed ``θ`` before the
    first sample of the new period at the last cycle's mean rate.

    Ports
    -----
    p : input, shape (3,), mm, not feedthrough
        Position.
    theta : input, rad, not feedthrough, default 0
        Estimated phase of the same tick.
    valid : input, bool, not feedthrough, default False
        Whether ``theta`` is an estimate. Left unconnected, only the first period is estimated.
    last_period : output, shape (capacity, 3), mm
        The samples of the last completed period in its first ``last_length`` rows (zeros after them).
    last_phases : output, shape (capacity,), rad
        The phase of each of those samples (unwrapped within the period).
    last_length : output, int64
        Their number (0 before the first period completes).
    last_duration : output, s
        The period's duration (0 before the first period completes).
    period_count : output, int64
        Number of periods completed so far; it changes exactly when ``last_period`` does.

    Parameters
    ----------
    h : float
        Segment length in s (in (0, 1]; 0.1 s = the deliverable's 10 samples at 100 Hz).
    capacity : int
        Longest period in samples that can be recorded (>= 10; 2400 = 10 s at 240 Hz). It must hold
        ``2 H + 3`` samples at the step the block runs at.
    start_speed : float
        Speed above which the motion has started, in spreads of the samples so far per second (>= 0).
    match_ratio : float
        Depth a local minimum of ``d`` must have, relative to its largest value so far, in (0, 1].
    min_period_fraction : float
        Shortest later period, as a share of the last cycle's duration, in [0, 1).

    Notes
    -----
    A period is stored when it completes; the outputs show it from the next tick. If the buffer
    fills before the first period is found, the search restarts from the next fast sample; if it
    fills during a later period (a missed wrap at a high rate), that period is dropped and
    recording starts again at the next wrap; the phase is unaffected, it goes on from the last
    customised reference. Bad data policy: a sample with a non-finite coordinate, or one beyond 1e100
    (a corrupted number in any unit), is skipped.
    """

    def __init__(
        self,
        *,
        h: float = 0.1,
        capacity: int = 2400,
        start_speed: float = 1.0,
        match_ratio: float = 0.3,
        min_period_fraction: float = 0.7,
        period: float | None = None,
    ) -> None:
        super().__init__(period=period)
        self.h = finite_number(self, "h", h, low=0.0, high=1.0, low_open=True)
        self.capacity = positive_int(self, "capacity", capacity, minimum=10)
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
        self.add_output("last_phases", shape=(cap,), unit="rad")
        self.add_output("last_length", COUNT)
        self.add_output("last_duration", shape=(), unit="s")
        self.add_output("period_count", COUNT)
        self.add_state("stage", _WAITING)
        self.add_state("tick", 0)
        self.add_state("previous", np.zeros(3))
        self.add_state("has_previous", False)
        self.add_state("rest_count", 0)  # samples seen while waiting, their mean and summed squared distance (Welford)
        self.add_state("rest_mean", np.zeros(3))
        self.add_state("rest_m2", 0.0)
        self.add_state("recording", np.zeros((cap, 3)))
        self.add_state("tags", np.zeros(cap))
        self.add_state("n", 0)
        self.add_state("d_recent", np.zeros((_SEGMENTS, 5)))  # d(k-4) ... d(k) of each first segment
        self.add_state("n_d", np.zeros(_SEGMENTS, dtype=np.int64))
        self.add_state("d_max", np.zeros(_SEGMENTS))
        self.add_state("theta_previous", 0.0)
        self.add_state("theta_previous_valid", False)
        self.add_state("phase_rate", 0.0)  # rad per tick of the first period, for samples with no estimate yet
        self.add_state("crossing", 0.0)  # tick at which the phase last crossed 2π
        self.add_state("cycle_ticks", 0.0)  # ticks per cycle of the last stored period
        self.add_state("stored", np.zeros((cap, 3)))
        self.add_state("stored_tags", np.zeros(cap))
        self.add_state("stored_length", 0)
        self.add_state("stored_duration", 0.0)
        self.add_state("stored_count", 0)

    def setup(self) -> None:
        self._h = segment_samples(self.h, self.dt)
        if self.capacity < 2 * self._h + 3:
            raise self._fail(
                f"capacity must hold 2 h + 3 = {2 * self._h + 3} samples at dt = {self.dt:g} s, got {self.capacity}"
            )

    def output(self, k: int) -> None:
        # the period output is large: copy it only when a new one has completed
        if self.period_count.value != self.stored_count:
            self.last_period.value[...] = self.stored
            self.last_phases.value[...] = self.stored_tags
            self.last_length.value[...] = self.stored_length
            self.last_duration.value[...] = self.stored_duration
            self.period_count.value[...] = self.stored_count

    def update(self, k: int) -> None:
        self.tick += 1
        p = self.p.value
        if not plausible(p, MEASURABLE):
            return
        if self.stage == _WAITING:
            self._wait_for_motion(p)
        elif self.stage == _FIRST:
            self._first_period(p)
        else:
            self._later_period(p)
        self.previous[...] = p
        self.has_previous = True

    def _wait_for_motion(self, p: np.ndarray) -> None:
        if self.has_previous and math.dist(p, self.previous) > self.start_speed * self.dt * self._spread():
            self.recording[0] = self.previous
            self.recording[1] = p
            self.n = 2
            self.n_d[...] = 0
            self.d_max[...] = 0.0
            self.stage = _FIRST
            return
        self.rest_count += 1
        step = p - self.rest_mean
        self.rest_mean += step / self.rest_count
        self.rest_m2 += float(step @ (p - self.rest_mean))

    def _spread(self) -> float:
        """Root mean square distance of the samples seen while waiting from their mean (0 for one sample)."""
        return math.sqrt(self.rest_m2 / self.rest_count) if self.rest_count else 0.0

    def _first_period(self, p: np.ndarray) -> None:
        if self.n == self.capacity:
            self.stage = _WAITING
            self.rest_count, self.rest_m2 = 0, 0.0  # the next moving sample starts afresh
            return
        rec, h = self.recording, self._h
        rec[self.n] = p
        self.n += 1
        newest = self.n - 1
        if newest <= h:
            return
        # the deliverable's segment distance for each of the first _SEGMENTS segments (offsets 0, H, 2H, ...)
        offsets = h * np.arange(_SEGMENTS)
        active = newest > offsets + h
        latest = rec[newest - h + 1 : newest + 1]
        firsts = rec[offsets[active, None] + np.arange(h)]  # (active segments, H, 3)
        d = np.linalg.norm(firsts - latest, axis=2).mean(axis=1)
        d += np.linalg.norm(np.diff(firsts, axis=1) - np.diff(latest, axis=0), axis=2).mean(axis=1)
        recent = self.d_recent[active]
        recent[:, :-1] = recent[:, 1:]
        recent[:, -1] = d
        self.d_recent[active] = recent
        self.n_d[active] += 1
        self.d_max[active] = np.maximum(self.d_max[active], d)
        centre = self.d_recent[:, 2]
        found = (
            (self.n_d >= 5)
            & (centre < self.match_ratio * self.d_max)
            & (centre < self.d_recent[:, 0])
            & (centre < self.d_recent[:, 1])
            & (centre < self.d_recent[:, 3])
            & (centre < self.d_recent[:, 4])
        )
        if found.any():
            segment = int(np.argmax(found))  # the earliest segment whose repeat was found (normally the first)
            recent = self.d_recent[segment]
            centre = recent[2]
            curvature = recent[1] - 2.0 * centre + recent[3]  # > 0: centre is a strict minimum
            delta = 0.5 * (recent[1] - recent[3]) / curvature
            length = newest - 2 - (h - 1) + delta - offsets[segment]  # M₁ = k_P2 - k_P1, in samples
            start = math.ceil(length)  # the first sample of the second period
            self.phase_rate = TWO_PI / length
            self.cycle_ticks = length
            self.tags[: self.n] = self.phase_rate * np.arange(self.n)
            self._store(start, length * self.dt)
            self.crossing = self.tick - self.n + 1 + length  # the tick of k_P2, a real number
            rest = self.n - start
            rec[:rest] = rec[start : self.n].copy()
            self.tags[:rest] = self.tags[start : self.n] - TWO_PI
            self.n = rest
            self.stage = _SYNCED

    def _later_period(self, p: np.ndarray) -> None:
        valid = bool(self.valid.value)
        theta = float(self.theta.value)
        previous = self.theta_previous
        wrapped = valid and self.theta_previous_valid and previous - theta > math.pi
        self.theta_previous = theta
        self.theta_previous_valid = valid
        if wrapped:
            # the crossing of 2π: θ ago at the mean rate (the same as interpolating when θ is small, and
            # right after a jump, such as a freeze that ends past the wrap)
            crossing = self.tick - theta * self.cycle_ticks / TWO_PI
            if self.stage == _RESYNC:
                self.n = 0
                self.stage = _SYNCED
            elif self.n >= 2 * self._h and crossing - self.crossing >= self.min_period_fraction * self.cycle_ticks:
                cycles = max(1.0, (self.tags[self.n - 1] - self.tags[0]) / TWO_PI)  # > 1 after a missed wrap
                self.cycle_ticks = (crossing - self.crossing) / round(cycles)
                self._store(self.n, (crossing - self.crossing) * self.dt)
                self.n = 0
            else:
                crossing = self.crossing  # jitter around 2π: the period goes on
            self.crossing = crossing
        if self.stage == _RESYNC or (self.has_previous and np.array_equal(p, self.previous)):
            return
        if self.n == self.capacity:
            self.stage = _RESYNC
            return
        self.recording[self.n] = p
        # before the phase computer has a reference, the first period's rate continues
        self.tags[self.n] = theta if valid else self.phase_rate * (self.tick - self.crossing)
        if self.n > 0:
            # unwrapped within the period, the motion going forward: a step from the last phase lies in
            # [−π/2, 3π/2) (jitter back across 2π, and a wrap missed or taken as jitter, are recognised)
            step = self.tags[self.n] - self.tags[self.n - 1]
            self.tags[self.n] -= TWO_PI * math.floor((step + 0.5 * math.pi) / TWO_PI)
        self.n += 1

    def _store(self, length: int, duration: float) -> None:
        self.stored[:length] = self.recording[:length]
        self.stored[length:] = 0.0
        self.stored_tags[:length] = self.tags[:length]
        self.stored_tags[length:] = 0.0
        self.stored_length = length
        self.stored_duration = duration
        self.stored_count += 1
