"""The phase computer of section 6: nearest point of the customised reference, θ = 2π (i* + δ)/G."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from cogblocks.blocks.angles import TWO_PI
from cogblocks.blocks.samples import MEASURABLE, plausible
from cogblocks.blocks.specs import COUNT, FLAG, PHASE, POSITION, VELOCITY
from cogblocks.sim import Block, Signal
from cogblocks.sim.params import finite_number, one_of

__all__ = ["PhaseComputer"]


class PhaseComputer(Block):
    """Phase of the current sample on the customised reference (section 6.1.2, "phase computer").

    ``i* = argmin_i D(i)``, ``D(i) = min_s ‖(p − c̄) − s (γ^c(i) − c̄)‖² + τ² ‖v − s γ̇^c(i)‖²``
    with ``c̄`` the reference's centroid and the amplitude ``s`` (closed form) within
    ``[1 / amplitude_range, amplitude_range]``, so that a cycle larger or smaller than the one the
    reference was fitted to does not slide the nearest point along the curve
    (``amplitude_range = 1`` gives the deliverable's distance). ``θ = 2π (i* + δ) / G``, the
    reference sampled on ``G`` points of a uniform phase grid and
    ``δ`` in ``[−½, ½]`` placing the minimum of the parabola through ``D(i* − 1 … i* + 1)``: the
    phase is continuous, not a multiple of the grid step. The velocity weight ``τ`` (in s) turns
    velocities into displacements; by default it is 0.01 s (one sample at 100 Hz, the
    deliverable's rate), the same at every rate.

    With ``search="warm"`` (footnote 5 of the deliverable) only the window ``i*(k−1) − w …
    i*(k−1) + w`` is searched, wrapping around the ends of the closed reference; ``w`` is the
    phase covered in ``window`` seconds at the reference's mean speed, ``ceil(G · window / T)``
    grid points (``T`` the duration of the period the reference was fitted to). The full
    search is run instead when there is no previous index on this reference (the first tick and
    every time a new customised reference arrives), when the window's minimum lies on its edge
    (the true minimum may be beyond it), and when the window's best distance exceeds
    ``jump_factor · max(D, distance_floor · σ)``, ``D`` being the distance found by the last full
    search (the motion has left the neighbourhood: a drop-out, a jump) and ``σ`` the customised
    reference's spread (root mean square distance of its rows from ``c̄``), so that the rule is
    the same in mm, m or sensor counts. On clean data, where the
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
    duration : input, s, default 0
        The duration of the period it was fitted to; not a positive number: every search is full.
    theta : output, rad, wrapped
        The phase, in ``[0, 2π)``.
    valid : output, bool
        False until the first customised reference arrives, that is, during the first period and
        until it has been detected; ``theta`` is held at 0 meanwhile.

    Parameters
    ----------
    search : {"warm", "full"}
        Windowed search around the last index, or a full search every tick.
    window : float
        Half-width of the warm-search window in s of motion (in (0, 1]; 0.1 s, 10 samples at 100 Hz).
    jump_factor : float
        Fall back to a full search when the distance grows beyond this multiple (> 1).
    distance_floor : float
        Smallest reference distance of the jump rule, in spreads of the customised reference (>= 0;
        0.04, 5 mm on the 120 mm spread of the synthetic primitive): noise alone must not trigger it.
    velocity_weight : float
        ``τ`` in s (>= 0; 0.01 s by default).
    extrapolate : float
        Longest frozen stretch in s (>= 0) over which the phase is extrapolated (0.5 s by default).
    amplitude_range : float
        Largest ratio between the cycle's amplitude and the reference's (>= 1; 1.3 by default).

    Notes
    -----
    A position equal to the last one (a frozen tracker: real motion never repeats a sample exactly)
    is not searched: the phase advances at the reference's mean speed, ``2π dt / T`` per tick, for
    up to ``extrapolate`` seconds, then holds; the next moving sample is searched afresh (a full
    search, as after any jump).

    Bad data policy: a tick with a non-finite position or velocity, or one beyond 1e100 (a corrupted number
    in any unit), holds the last phase; so does a tick whose nearest reference row is not finite (an implausible row
    overflows to an infinite distance and is never the nearest).
    """

    def __init__(
        self,
        *,
        search: str = "warm",
        window: float = 0.1,
        jump_factor: float = 3.0,
        distance_floor: float = 0.04,
        velocity_weight: float = 0.01,
        extrapolate: float = 0.5,
        amplitude_range: float = 1.3,
        period: float | None = None,
    ) -> None:
        super().__init__(period=period)
        self.search = one_of(self, "search", search, ("warm", "full"))
        self.window = finite_number(self, "window", window, low=0.0, high=1.0, low_open=True)
        self.jump_factor = finite_number(self, "jump_factor", jump_factor, low=1.0, low_open=True)
        self.distance_floor = finite_number(self, "distance_floor", distance_floor, low=0.0)
        self.velocity_weight = finite_number(self, "velocity_weight", velocity_weight, low=0.0)
        self.extrapolate = finite_number(self, "extrapolate", extrapolate, low=0.0)
        self.amplitude_range = finite_number(self, "amplitude_range", amplitude_range, low=1.0)
        self.add_input("p", POSITION)
        self.add_input("v", VELOCITY)
        self.add_input("positions", Signal(shape=None, unit="mm"))
        self.add_input("velocities", Signal(shape=None, unit="mm/s"))
        self.add_input("length", COUNT)
        self.add_input("count", COUNT)
        self.add_input("duration", Signal(shape=(), unit="s"), default=0.0)
        self.add_output("theta", PHASE)
        self.add_output("valid", FLAG)
        self.add_state("index", -1)  # i*(k-1) on the reference numbered ref_count; -1: none
        self.add_state("ref_count", 0)
        self.add_state("full_distance", 0.0)
        self.add_state("last_p", np.full(3, np.nan))
        self.add_state("frozen", 0)  # ticks the position has been repeated exactly
        self.add_scratch("_next", (-1, 0, 0.0))  # what output() decided, committed by update()
        self.add_scratch("_next_frozen", 0)
        # a cache of the reference's centre and spread, keyed by the reference's count input
        self.add_scratch("_centre_of", -1)
        self.add_scratch("_centre_value", np.zeros(3))
        self.add_scratch("_spread", 0.0)

    def setup(self) -> None:
        shape = self.positions.spec.shape
        if len(shape) != 2 or shape[1] != 3 or self.velocities.spec.shape != shape:
            raise self._fail(
                f"positions and velocities must both have shape (capacity, 3), got {shape} and "
                f"{self.velocities.spec.shape}"
            )
        self._tau2 = self.velocity_weight**2

    def _centre(self, m: int) -> np.ndarray:
        """The customised reference's centroid (and spread), computed once per reference (the warm search stays
        O(window))."""
        count = int(self.count.value)
        if count != self._centre_of:
            with np.errstate(over="ignore", invalid="ignore"):
                rows = self.positions.value[:m]
                self._centre_value = rows.mean(axis=0)
                self._spread = float(np.sqrt(((rows - self._centre_value) ** 2).sum(axis=1).mean()))
            self._centre_of = count
        return self._centre_value

    def _squared_distance(self, rows: Any, m: int) -> np.ndarray:
        # a corrupt reference row overflows to inf (never the nearest) or gives NaN (checked by the caller)
        with np.errstate(over="ignore", invalid="ignore"):
            centre = self._centre(m)
            g = self.positions.value[rows] - centre
            gv = self.velocities.value[rows]
            a, v = self.p.value - centre, self.v.value
            tau2 = self._tau2
            # ‖a − s g‖² + τ²‖v − s ġ‖² = A − 2 s B + s² C, at the best amplitude s within the allowed range
            b = g @ a + tau2 * (gv @ v)
            c = np.einsum("ij,ij->i", g, g) + tau2 * np.einsum("ij,ij->i", gv, gv)
            r = self.amplitude_range
            s = np.clip(b / np.where(c > 0.0, c, 1.0), 1.0 / r, r)
            return (a @ a + tau2 * (v @ v)) - 2.0 * s * b + s * s * c

    def output(self, k: int) -> None:
        self._next = (self.index, self.ref_count, self.full_distance)
        count = int(self.count.value)
        if count == 0 or not (plausible(self.p.value, MEASURABLE) and plausible(self.v.value, MEASURABLE)):
            return
        m = int(self.length.value)
        duration = float(self.duration.value)
        self._next_frozen = 0
        if np.array_equal(self.p.value, self.last_p) and 0.0 < duration < math.inf and self.index >= 0:
            # a frozen sensor: the hand moves on at the reference's mean speed, for at most `extrapolate` s
            self._next_frozen = self.frozen + 1
            if self._next_frozen * self.dt <= self.extrapolate:
                self.theta.value[...] = (float(self.theta.value) + TWO_PI * self.dt / duration) % TWO_PI
            return
        # the warm window: the phase covered in `window` seconds, in grid points (NaN fails the test)
        w = math.ceil(m * self.window / duration) if 0.0 < duration < math.inf else m
        if self.search == "warm" and self.index >= 0 and count == self.ref_count and 2 * w + 1 < m:
            rows = (self.index + np.arange(-w, w + 1)) % m
            d2 = self._squared_distance(rows, m)
            j = int(np.argmin(d2))
            limit = self.jump_factor * max(self.full_distance, self.distance_floor * self._spread)
            if 0 < j < 2 * w and d2[j] <= limit * limit:
                self._emit(int(rows[j]), m, count, self.full_distance, d2[j - 1 : j + 2])
                return
        d2 = self._squared_distance(slice(0, m), m)
        i = int(np.argmin(d2))
        if math.isfinite(d2[i]):  # NaN (argmin's pick when present) or all-inf: a corrupt reference, hold
            self._emit(i, m, count, math.sqrt(d2[i]), d2[[(i - 1) % m, i, (i + 1) % m]])

    def _emit(self, i: int, m: int, count: int, full_distance: float, around: np.ndarray) -> None:
        before, at, after = (float(x) for x in around)
        curvature = before - 2.0 * at + after
        # between grid points: the vertex of the parabola through the three distances (none if it is not convex)
        delta = 0.5 * (before - after) / curvature if curvature > 0.0 and math.isfinite(curvature) else 0.0
        theta = (TWO_PI * (i + min(0.5, max(-0.5, delta))) / m) % TWO_PI
        self.theta.value[...] = theta if theta < TWO_PI else 0.0  # -1e-18 % 2π rounds to 2π
        self.valid.value[...] = True
        self._next = (i, count, full_distance)

    def update(self, k: int) -> None:
        self.index, self.ref_count, self.full_distance = self._next
        self.frozen = self._next_frozen
        if plausible(self.p.value, MEASURABLE):
            self.last_p[...] = self.p.value
