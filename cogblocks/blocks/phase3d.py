"""Phase of a quasi-periodic 3D motion, online, and position from phase (section 6 of the deliverable).

Position to phase (section 6.1, Figure 11) is four blocks, wired together by
:class:`PhaseEstimator3D`::

    p ─┬─> BackwardDifference ─── v ──────────────────────────────────────┐
       ├─> PeriodEstimator ─> ReferenceCustomizer ─── γ^c, γ̇^c ───────────┤
       └──────────────────────────────────────────────────────────────────┴─> PhaseComputer ─> θ, valid
           PeriodEstimator <── θ, valid (fed back, read only in update) ──────────────┘

Phase to position (section 6.2, Figure 15) is :class:`PositionComputer`. The offline benchmark of
section 6.1.3 (PCA, then the Hilbert phase) is :func:`offline_phase_pca_hilbert`.

Conventions: positions in mm, velocities in mm/s, phases in rad wrapped to ``[0, 2π)`` with 0 at
the start of the reference motion. A period or customised reference travels between blocks as a
fixed-capacity ``(capacity, 3)`` array plus its length (the valid rows) and a counter that goes up
by one each time a new period completes, so nothing is allocated while the diagram runs.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import scipy.signal

from cogblocks.blocks.angles import TWO_PI, wrap_2pi
from cogblocks.blocks.estimation import KalmanEstimator
from cogblocks.blocks.samples import plausible
from cogblocks.sim import ANY, Block, Diagram, Signal
from cogblocks.sim.params import finite_array, finite_number, one_of, positive_int, random_generator

__all__ = [
    "BackwardDifference",
    "PeriodEstimator",
    "PhaseComputer",
    "PhaseEstimator3D",
    "PositionComputer",
    "ReferenceCustomizer",
    "customize_reference",
    "kabsch_rotation",
    "offline_phase_pca_hilbert",
]

POSITION = Signal(shape=(3,), unit="mm")
VELOCITY = Signal(shape=(3,), unit="mm/s")
PHASE = Signal(unit="rad", wrapped=True)
COUNT = Signal(dtype=np.int64, unit="1")
FLAG = Signal(dtype=np.bool_, unit="1")

# Stages of the period estimator.
_WAITING = 0  # the hand has not moved yet
_FIRST = 1  # recording the first period, looking for the end of it by segment matching
_SYNCED = 2  # recording a later period, which ends when the estimated phase wraps
_RESYNC = 3  # a later period overflowed the buffer: wait for the next wrap to start afresh

# Offline phase: share of a cycle skipped at the start of a record when measuring the first cycle,
# and the number of passes of the Hilbert transform with periodic padding.
_EDGE_SHARE = 0.05
_PADDED_PASSES = 2
_PAD_CYCLES = 3

# A degenerate reference axis: its spread is below this share of the largest spread.
_DEGENERATE = 1e-9


def _as_curve(owner: str, name: str, value: Any, minimum: int) -> np.ndarray:
    arr = finite_array(owner, name, value, shape=(None, 3))
    if len(arr) < minimum:
        raise ValueError(f"{owner}: {name} must have at least {minimum} samples, got {len(arr)}")
    return arr


def kabsch_rotation(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The proper rotation that best maps centred points ``source`` onto ``target`` (Arun et al. 1987).

    Minimises ``Σ_i ‖R q_i − p_i‖²`` over rotations with ``det R = +1``: with the cross-covariance
    ``H = Σ_i q_i p_iᵀ = U Σ Vᵀ``, ``R = V Uᵀ``, and the last column of ``V`` is negated when that
    would be a reflection (``det < 0``), which gives the best proper rotation instead.

    Parameters
    ----------
    source, target : numpy.ndarray, shape (n, 3)
        Corresponding points ``q_i`` and ``p_i``, both already centred.

    Returns
    -------
    numpy.ndarray, shape (3, 3)
        ``R``, to be applied as ``R @ q`` (or ``source @ R.T``).
    """
    u, _, vt = np.linalg.svd(source.T @ target)
    v = vt.T
    if np.linalg.det(v @ u.T) < 0.0:
        v[:, -1] = -v[:, -1]
    return v @ u.T


def customize_reference(reference: Any, period: Any, dt: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Fit the reference motion to one recorded period: the customised reference γ^c (section 6.1.2 b).

    1. Resample the closed reference curve to the period's number of samples ``M`` by linear
       interpolation (sample ``j`` sits at phase ``2π j / M``).
    2. Centre both curves.
    3. Scale the reference along each axis by ``σ(period) / σ(reference)``; an axis along which the
       reference does not move keeps a factor of 1 (the ratio is undefined there, and the axis has
       nothing to scale).
    4. Rotate it by the proper rotation of :func:`kabsch_rotation` (no reflection).
    5. Move it to the period's centroid.

    Velocities are backward differences along the closed curve (the first sample's predecessor is
    the last), divided by ``dt``.

    Parameters
    ----------
    reference : array_like, shape (N, 3)
        The reference motion γ_ref, one cycle from phase 0, in mm (N >= 2).
    period : array_like, shape (M, 3)
        The recorded period γ_ℓ in mm (M >= 2).
    dt : float
        Sampling time of the period in s (> 0); ``1`` gives velocities in mm per sample.

    Returns
    -------
    positions : numpy.ndarray, shape (M, 3)
        γ^c in mm.
    velocities : numpy.ndarray, shape (M, 3)
        Its backward-difference velocity in mm/s (mm per sample for ``dt = 1``).

    Examples
    --------
    >>> phi = 2 * np.pi * np.arange(100) / 100
    >>> ref = np.stack([np.cos(phi), np.sin(phi), 0 * phi], axis=1)
    >>> pos, vel = customize_reference(ref, 10 * ref[::2] + 5)
    >>> bool(np.allclose(pos, 10 * ref[::2] + 5))
    True
    """
    owner = "customize_reference"
    ref = _as_curve(owner, "reference", reference, 2)
    per = _as_curve(owner, "period", period, 2)
    dt = finite_number(owner, "dt", dt, low=0.0, low_open=True)
    return _customize(ref, per, dt)


def _customize(ref: np.ndarray, per: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`customize_reference` on checked arrays (the block calls this once per period)."""
    n, m = len(ref), len(per)
    at = np.arange(m) * (n / m)
    below = at.astype(np.intp)
    frac = (at - below)[:, None]
    resampled = ref[below] * (1.0 - frac) + ref[(below + 1) % n] * frac  # the curve is closed
    q = resampled - resampled.mean(axis=0)
    centroid = per.mean(axis=0)
    p = per - centroid
    sd_ref, sd_per = q.std(axis=0), p.std(axis=0)
    moving = sd_ref > _DEGENERATE * max(float(sd_ref.max()), 1.0)
    scale = np.ones(3)
    scale[moving] = sd_per[moving] / sd_ref[moving]
    q *= scale
    positions = q @ kabsch_rotation(q, p).T + centroid
    velocities = (positions - np.roll(positions, 1, axis=0)) / dt
    return positions, velocities


class BackwardDifference(Block):
    """Backward-difference derivative: ``y[k] = (u[k] − u[k−1]) / dt``, ``y[0] = 0``.

    Ports: input ``u`` (any shape), output ``y`` (spec of ``u`` with ``/s`` appended to the unit,
    not wrapped).

    Notes
    -----
    Bad data policy: a non-finite sample gives a non-finite output and is not remembered; the next
    finite sample is differenced against the last finite one.
    """

    def __init__(self, *, period: float | None = None) -> None:
        super().__init__(period=period)
        self.add_input("u", ANY)
        self.add_output("y", like="u", unit=lambda unit: f"{unit}/s", wrapped=False)
        self.add_state("last", np.zeros(()))
        self.add_state("primed", False)

    def setup(self) -> None:
        self.add_state("last", np.zeros(self.u.spec.shape))

    def output(self, k: int) -> None:
        if self.primed:
            np.subtract(self.u.value, self.last, out=self.y.value)
            self.y.value /= self.dt
        else:
            self.y.value[...] = 0.0

    def update(self, k: int) -> None:
        if np.all(np.isfinite(self.u.value)):
            self.last[...] = self.u.value
            self.primed = True


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


class ReferenceCustomizer(Block):
    """Fit the reference motion to the last completed period (section 6.1.2 b).

    Runs :func:`customize_reference` each time a new period arrives (when ``period_count``
    changes) and holds the result in between.

    Ports
    -----
    last_period : input, shape (capacity, 3), mm
        The last completed period, in its first ``last_length`` rows.
    last_length, period_count : input, int64
        Its length and the period counter (see :class:`PeriodEstimator`).
    positions : output, shape (capacity, 3), mm
        The customised reference γ^c in its first ``length`` rows (zeros after them).
    velocities : output, shape (capacity, 3), mm/s
        Its backward-difference velocity, in the same rows.
    length : output, int64
        Number of samples of γ^c (the period's length ``M_ℓ``; 0 before the first period).
    count : output, int64
        The period counter γ^c was made from (0: no customised reference yet).

    Parameters
    ----------
    reference : array_like, shape (N, 3)
        The reference motion γ_ref, one cycle from phase 0, in mm (N >= 2).

    Notes
    -----
    Bad data policy: a period with a non-finite or implausible (beyond 1 km)
    coordinate is not fitted; the previous customised reference holds.
    """

    def __init__(self, reference: Any, *, period: float | None = None) -> None:
        super().__init__(period=period)
        self.reference = _as_curve("ReferenceCustomizer", "reference", reference, 2)
        self.add_input("last_period", Signal(shape=None, unit="mm"))
        self.add_input("last_length", COUNT)
        self.add_input("period_count", COUNT)
        self.add_output("positions", like="last_period")
        self.add_output("velocities", like="last_period", unit="mm/s")
        self.add_output("length", COUNT)
        self.add_output("count", COUNT)

    def setup(self) -> None:
        shape = self.last_period.spec.shape
        if len(shape) != 2 or shape[1] != 3 or shape[0] < 2:
            raise self._fail(f"last_period must have shape (capacity, 3) with capacity >= 2, got {shape}")

    def output(self, k: int) -> None:
        count = int(self.period_count.value)
        if count == self.count.value:
            return
        m = int(self.last_length.value)
        if m < 2 or not plausible(self.last_period.value[:m]):
            return
        positions, velocities = _customize(self.reference, self.last_period.value[:m], self.dt)
        self.positions.value[:m] = positions
        self.positions.value[m:] = 0.0
        self.velocities.value[:m] = velocities
        self.velocities.value[m:] = 0.0
        self.length.value[...] = m
        self.count.value[...] = count


class PhaseComputer(Block):
    """Phase of the current sample on the customised reference (section 6.1.2, "phase computer").

    ``i* = argmin_i ‖p − γ^c(i)‖² + τ² ‖v − γ̇^c(i)‖²`` and ``θ = 2π i* / M``. The velocity weight
    ``τ`` (in s) turns velocities into displacements; by default it is the block's step, so the
    velocity term compares the displacements over one sample, the way the backward differences
    were taken.

    With ``search="warm"`` (footnote 5 of the deliverable) only the window ``i*(k−1) − window …
    i*(k−1) + window`` is searched, wrapping around the ends of the closed reference. The full
    search is run instead when there is no previous index on this reference (the first tick and
    every time a new customised reference arrives), when the window's minimum lies on its edge
    (the true minimum may be beyond it), and when the window's best distance exceeds
    ``jump_factor · max(D, distance_floor)``, ``D`` being the distance found by the last full
    search (the motion has left the neighbourhood: a drop-out, a jump). On clean data, where the
    nearest sample moves by about one index per tick, the warm search returns the full search's
    index.

    Ports
    -----
    p : input, shape (3,), mm
        Position.
    v : input, shape (3,), mm/s
        Velocity.
    positions, velocities, length, count : input
        The customised reference (see :class:`ReferenceCustomizer`).
    theta : output, rad, wrapped
        The phase, in ``[0, 2π)``.
    valid : output, bool
        False until the first customised reference arrives, that is, during the first period and
        until it has been detected; ``theta`` is held at 0 meanwhile.

    Parameters
    ----------
    search : {"warm", "full"}
        Windowed search around the last index, or a full search every tick.
    window : int
        Half-width of the warm-search window in samples (>= 1).
    jump_factor : float
        Fall back to a full search when the distance grows beyond this multiple (> 1).
    distance_floor : float
        Smallest reference distance of the jump rule, in mm (>= 0): noise alone must not trigger it.
    velocity_weight : float, optional
        ``τ`` in s (>= 0); the block's step by default.

    Notes
    -----
    Bad data policy: a tick with a non-finite or implausible (beyond 1 km, or 1 km/s) position or velocity
    holds the last phase.
    """

    def __init__(
        self,
        *,
        search: str = "warm",
        window: int = 10,
        jump_factor: float = 3.0,
        distance_floor: float = 5.0,
        velocity_weight: float | None = None,
        period: float | None = None,
    ) -> None:
        super().__init__(period=period)
        self.search = one_of(self, "search", search, ("warm", "full"))
        self.window = positive_int(self, "window", window)
        self.jump_factor = finite_number(self, "jump_factor", jump_factor, low=1.0, low_open=True)
        self.distance_floor = finite_number(self, "distance_floor", distance_floor, low=0.0)
        self.velocity_weight = (
            None if velocity_weight is None else finite_number(self, "velocity_weight", velocity_weight, low=0.0)
        )
        self.add_input("p", POSITION)
        self.add_input("v", VELOCITY)
        self.add_input("positions", Signal(shape=None, unit="mm"))
        self.add_input("velocities", Signal(shape=None, unit="mm/s"))
        self.add_input("length", COUNT)
        self.add_input("count", COUNT)
        self.add_output("theta", PHASE)
        self.add_output("valid", FLAG)
        self.add_state("index", -1)  # i*(k-1) on the reference numbered ref_count; -1: none
        self.add_state("ref_count", 0)
        self.add_state("full_distance", 0.0)
        self._offsets = np.arange(-self.window, self.window + 1)
        self._next = (-1, 0, 0.0)

    def setup(self) -> None:
        shape = self.positions.spec.shape
        if len(shape) != 2 or shape[1] != 3 or self.velocities.spec.shape != shape:
            raise self._fail(
                f"positions and velocities must both have shape (capacity, 3), got {shape} and "
                f"{self.velocities.spec.shape}"
            )
        tau = self.dt if self.velocity_weight is None else self.velocity_weight
        self._tau2 = tau * tau

    def _squared_distance(self, rows: Any) -> np.ndarray:
        dp = self.positions.value[rows] - self.p.value
        dv = self.velocities.value[rows] - self.v.value
        return np.einsum("ij,ij->i", dp, dp) + self._tau2 * np.einsum("ij,ij->i", dv, dv)

    def output(self, k: int) -> None:
        self._next = (self.index, self.ref_count, self.full_distance)
        count = int(self.count.value)
        if count == 0 or not (plausible(self.p.value) and plausible(self.v.value)):
            return
        m = int(self.length.value)
        w = self.window
        if self.search == "warm" and self.index >= 0 and count == self.ref_count and 2 * w + 1 < m:
            rows = (self.index + self._offsets) % m
            d2 = self._squared_distance(rows)
            j = int(np.argmin(d2))
            limit = self.jump_factor * max(self.full_distance, self.distance_floor)
            if 0 < j < 2 * w and d2[j] <= limit * limit:
                self._emit(int(rows[j]), m, count, self.full_distance)
                return
        d2 = self._squared_distance(slice(0, m))
        i = int(np.argmin(d2))
        self._emit(i, m, count, math.sqrt(d2[i]))

    def _emit(self, i: int, m: int, count: int, full_distance: float) -> None:
        self.theta.value[...] = TWO_PI * i / m
        self.valid.value[...] = True
        self._next = (i, count, full_distance)

    def update(self, k: int) -> None:
        self.index, self.ref_count, self.full_distance = self._next


class PhaseEstimator3D(Diagram):
    """Online phase of a quasi-periodic 3D motion (section 6.1, Figure 11), as one block.

    A :class:`BackwardDifference` (named ``velocity``) gives the velocity from the positions, a
    :class:`PeriodEstimator` (``period``) records the last completed period, a
    :class:`ReferenceCustomizer` (``customizer``) fits the reference to it and a
    :class:`PhaseComputer` (``phase``) finds the phase on the fitted reference; the phase is fed
    back to the period estimator, which ends the later periods where it wraps. The velocity is
    computed inside, by the same backward difference as the reference's velocity, so that the two
    match in noise and lag; give a smoothed position if the sensor is noisy.

    With ``velocity="kalman"`` a :class:`~cogblocks.blocks.estimation.KalmanEstimator` named
    ``kalman`` (``kalman_model``, three axes, its defaults for arm motion in mm) replaces the
    backward difference: its ``p_hat`` goes to the period estimator and the phase computer in place
    of the raw position, its ``v_hat`` to the phase computer in place of the differences. It
    smooths the noise and predicts through missing and frozen samples.

    Ports
    -----
    p : input, shape (3,), mm
        Position of the tracked point.
    theta : output, rad, wrapped
        Estimated phase in ``[0, 2π)``, 0 at the start of the reference motion; held at 0 while
        ``valid`` is False.
    valid : output, bool
        False during the first period (and until its end has been detected), True after.

    Parameters
    ----------
    reference : array_like, shape (N, 3)
        The reference motion γ_ref, one cycle from phase 0, in mm.
    h, capacity, start_speed, match_ratio, min_period_fraction
        See :class:`PeriodEstimator`.
    search, window, jump_factor, distance_floor, velocity_weight
        See :class:`PhaseComputer`.
    velocity : {"difference", "kalman"}
        Backward differences of the raw position (default) or the Kalman front end above.
    kalman_model : {"cv", "ca"}
        Model of that Kalman filter (``"ca"`` by default); unused with ``velocity="difference"``.

    Notes
    -----
    Bad data policy: a non-finite or implausible (beyond 1 km) sample gives a bad velocity inside,
    on which the period estimator skips the sample and the phase computer holds the phase; with
    ``velocity="kalman"`` the filter predicts through it instead. ``theta`` is never NaN.
    """

    def __init__(
        self,
        reference: Any,
        *,
        h: int = 10,
        capacity: int = 1000,
        start_speed: float = 50.0,
        match_ratio: float = 0.3,
        min_period_fraction: float = 0.7,
        search: str = "warm",
        window: int = 10,
        jump_factor: float = 3.0,
        distance_floor: float = 5.0,
        velocity_weight: float | None = None,
        velocity: str = "difference",
        kalman_model: str = "ca",
        period: float | None = None,
    ) -> None:
        super().__init__(period=period)
        self.velocity = one_of(self, "velocity", velocity, ("difference", "kalman"))
        self.kalman_model = one_of(self, "kalman_model", kalman_model, ("cv", "ca"))
        reference = _as_curve("PhaseEstimator3D", "reference", reference, 2)
        if velocity == "kalman":
            front = self.add("kalman", KalmanEstimator(kalman_model, dims=3, unit="mm"))
        else:
            front = self.add("velocity", BackwardDifference())
        estimator = self.add(
            "period",
            PeriodEstimator(
                h=h,
                capacity=capacity,
                start_speed=start_speed,
                match_ratio=match_ratio,
                min_period_fraction=min_period_fraction,
            ),
        )
        customizer = self.add("customizer", ReferenceCustomizer(reference))
        phase = self.add(
            "phase",
            PhaseComputer(
                search=search,
                window=window,
                jump_factor=jump_factor,
                distance_floor=distance_floor,
                velocity_weight=velocity_weight,
            ),
        )
        self.connect(estimator.last_period, customizer.last_period)
        self.connect(estimator.last_length, customizer.last_length)
        self.connect(estimator.period_count, customizer.period_count)
        self.connect(customizer.positions, phase.positions)
        self.connect(customizer.velocities, phase.velocities)
        self.connect(customizer.length, phase.length)
        self.connect(customizer.count, phase.count)
        self.connect(phase.theta, estimator.theta)
        self.connect(phase.valid, estimator.valid)
        if velocity == "kalman":
            self.connect(front.p_hat, estimator.p, phase.p)
            self.connect(front.v_hat, phase.v)
            self.expose_input("p", front.p)
        else:
            self.connect(front.y, phase.v)
            self.expose_input("p", front.u, estimator.p, phase.p)
        self.expose_output("theta", phase.theta)
        self.expose_output("valid", phase.valid)


class PositionComputer(Block):
    """Position on the reference motion for a phase (section 6.2, Figure 15).

    ``i = round(N θ / 2π) mod N`` (halves rounded up) and ``p = γ_ref(i)``, plus optional white
    Gaussian noise of standard deviation ``noise_std`` per axis, to make the motion look human.

    Ports
    -----
    theta : input, rad (wrapped or not)
        Phase.
    reference : input, shape (N, 3), mm, optional
        The reference motion, for a time-varying one (for instance a customised reference of N
        samples); unconnected, it is the constant ``reference`` given to the constructor.
    p : output, shape (3,), mm
        Position.

    Parameters
    ----------
    reference : array_like, shape (N, 3)
        The reference motion γ_ref, one cycle from phase 0, in mm (N >= 1). Fixes N.
    noise_std : float
        Standard deviation of the added noise in mm (>= 0; 0 by default).
    seed : int or numpy.random.Generator, optional
        Seed of the noise. The generator is part of the block's state, so ``reset()`` and
        ``load_state_dict()`` replay the same noise.

    Notes
    -----
    Bad data policy: a non-finite phase, or a non-finite element in the reference sample it
    selects, holds the last position (the reference may come from an upstream estimate).
    """

    def __init__(
        self,
        reference: Any,
        *,
        noise_std: float = 0.0,
        seed: int | np.random.Generator | None = None,
        period: float | None = None,
    ) -> None:
        super().__init__(period=period)
        ref = _as_curve("PositionComputer", "reference", reference, 1)
        self.n_samples = len(ref)
        self.noise_std = finite_number(self, "noise_std", noise_std, low=0.0)
        self.add_input("theta", Signal(unit="rad", wrapped=None))
        self.add_input("reference", shape=ref.shape, unit="mm", default=ref)
        self.add_output("p", POSITION, initial=ref[0])
        rng = random_generator(self, "seed", seed)
        # the noise of a tick is drawn in the previous tick's update, so output() leaves the state alone
        self.add_state("noise", self._draw(rng))
        self.add_state("rng", rng)

    def _draw(self, rng: np.random.Generator) -> np.ndarray:
        return rng.normal(scale=self.noise_std, size=3) if self.noise_std > 0 else np.zeros(3)

    def output(self, k: int) -> None:
        theta = float(self.theta.value)
        if not math.isfinite(theta):
            return
        i = math.floor(self.n_samples * theta / TWO_PI + 0.5) % self.n_samples
        sample = self.reference.value[i]
        if np.isfinite(sample).all():
            np.add(sample, self.noise, out=self.p.value)

    def update(self, k: int) -> None:
        self.noise = self._draw(self.rng)


def offline_phase_pca_hilbert(positions: np.ndarray) -> np.ndarray:
    """Offline phase of a recorded 3D motion: PCA, then the Hilbert phase (section 6.1.3).

    The centred positions are projected on their first principal direction and the phase is the
    unwrapped angle of the analytic signal (``scipy.signal.hilbert``) of that projection.

    *Edge effects.* The FFT behind the Hilbert transform treats the record as periodic, so the
    jump between its last and first samples distorts the phase near both ends (the first sample
    can be off by radians, the next tens of samples by tenths of a radian). The projection is
    therefore extended by three cycles at each end, periodically (the first cycle repeated before
    the start, the last after the end), before the transform. The cycle length comes from the
    previous pass: the (interpolated) number of samples the phase takes to gain 2π, counted from
    5 % of a cycle in; two padded passes follow one plain pass.

    *Alignment.* The phase increases with time whatever the sign of the principal direction; the
    sign (fixed so that the direction's largest component is positive) and the Hilbert convention
    (phase 0 at a maximum of the projection) only shift it by a constant. That constant is set to
    the online convention, phase 0 at the start of the motion and one turn per cycle (assumption 3
    of section 6.1.1): over the first cycle, of ``K`` samples (``K`` fractional), the circular mean
    of ``2π k / K − φ(k)`` is removed. Averaging over a whole cycle cancels the noise and most of the
    ripple the Hilbert phase has within a cycle of a non-sinusoidal motion.

    Parameters
    ----------
    positions : numpy.ndarray, shape (n, 3)
        The whole recording in mm, at a constant sampling rate; at least one full cycle.

    Returns
    -------
    numpy.ndarray, shape (n,)
        Phase in rad, wrapped to ``[0, 2π)``.

    Raises
    ------
    ValueError
        If the positions are not an (n, 3) array of finite numbers, or hold less than one cycle.
    """
    owner = "offline_phase_pca_hilbert"
    x = _as_curve(owner, "positions", positions, 4)
    centred = x - x.mean(axis=0)
    direction = np.linalg.svd(centred, full_matrices=False)[2][0]
    direction *= np.sign(direction[np.argmax(np.abs(direction))])
    signal = centred @ direction
    phase = np.unwrap(np.angle(scipy.signal.hilbert(signal)))
    for _ in range(_PADDED_PASSES):
        cycle = _first_cycle(phase, owner)
        # a mean over a whole number of cycles: a partial cycle leaves an offset that ripples the phase
        signal = signal - signal[: round(len(signal) // cycle * cycle)].mean()
        c = round(cycle)
        pad = _PAD_CYCLES * c
        padded = np.concatenate([np.tile(signal[:c], _PAD_CYCLES), signal, np.tile(signal[-c:], _PAD_CYCLES)])
        phase = np.unwrap(np.angle(scipy.signal.hilbert(padded)))[pad : pad + len(signal)]
    cycle = _first_cycle(phase, owner)
    k = np.arange(round(cycle))
    offset = np.angle(np.exp(1j * (TWO_PI * k / cycle - phase[k])).mean())
    return wrap_2pi(phase + offset)


def _first_cycle(phase: np.ndarray, owner: str) -> float:
    """Samples (interpolated) the unwrapped phase takes to gain 2π, from 5 % of a median cycle in."""
    step = float(np.median(np.diff(phase)))
    skip = math.ceil(_EDGE_SHARE * TWO_PI / step) if step > 0.0 else 0
    gained = phase[skip:] - phase[min(skip, len(phase) - 1)]
    past = np.flatnonzero(gained >= TWO_PI)
    if step <= 0.0 or past.size == 0:
        raise ValueError(
            f"{owner}: positions must hold at least one full cycle of the motion, got {len(phase)} samples"
        )
    j = int(past[0])  # >= 1, since gained[0] = 0
    return j - 1 + (TWO_PI - gained[j - 1]) / (gained[j] - gained[j - 1])
