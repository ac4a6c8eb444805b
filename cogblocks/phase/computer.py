"""The phase computer of section 6: nearest point of the customised reference, θ = 2π i*/M."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from cogblocks.blocks.angles import TWO_PI
from cogblocks.blocks.samples import plausible
from cogblocks.blocks.specs import COUNT, FLAG, PHASE, POSITION, VELOCITY
from cogblocks.sim import Block, Signal
from cogblocks.sim.params import finite_number, one_of, positive_int

__all__ = ["PhaseComputer"]


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
    holds the last phase; so does a tick whose nearest reference row is not finite (an implausible row
    overflows to an infinite distance and is never the nearest).
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
        # a corrupt reference row overflows to inf (never the nearest) or gives NaN (checked by the caller)
        with np.errstate(over="ignore", invalid="ignore"):
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
        if math.isfinite(d2[i]):  # NaN (argmin's pick when present) or all-inf: a corrupt reference, hold
            self._emit(i, m, count, math.sqrt(d2[i]))

    def _emit(self, i: int, m: int, count: int, full_distance: float) -> None:
        self.theta.value[...] = TWO_PI * i / m
        self.valid.value[...] = True
        self._next = (i, count, full_distance)

    def update(self, k: int) -> None:
        self.index, self.ref_count, self.full_distance = self._next
