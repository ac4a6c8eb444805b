"""A limit on the altered velocity's per-tick step, set by the human's own steps so far."""

from __future__ import annotations

import numpy as np

from cogblocks.blocks.specs import VELOCITY
from cogblocks.sim import Block
from cogblocks.sim.params import finite_number

__all__ = ["STEP_LIMIT", "VelocityStepLimiter"]

#: The ready diagrams' step limit, a multiple of the human's largest per-tick step so far. At 1 the altered
#: movement never steps harder than the human's own; below 1 it falls behind the human's fastest changes and
#: misses its end point (docs/explanation/avatar-naturalness.md, the trade-off table of the inner split).
STEP_LIMIT = 1.0


class VelocityStepLimiter(Block):
    """``v_a`` follows ``v`` with per-tick steps of at most ``factor`` × the human's largest step so far.

    The blending rules switch: ``c`` at each decision, the reference when the projector picks another,
    the optimised blender's emission at its last commit. Each switch is a step of the altered velocity in
    one tick, larger than any the human makes. This block lets ``v_a`` move towards ``v`` by at most
    ``max(floor, factor · max_{j ≤ k} ‖v_h(j) − v_h(j − 1)‖)`` (mm/s) per tick, in the step's direction, and
    follows ``v`` exactly whenever it can. With ``factor ≤ 1`` (and ``floor`` no larger than the human's
    largest step) the altered movement's largest step is at most the human's, by construction; the lag it
    leaves behind a switch is the price, a position error of about ``dt · S² / (2·limit)`` for a step ``S``.

    Ports
    -----
    v : input, shape (3,), mm/s
        The altered velocity as the blending rule made it.
    v_h : input, shape (3,), mm/s
        The human velocity.
    v_a : output, shape (3,), mm/s
        The limited altered velocity.

    Parameters
    ----------
    factor : float
        The limit as a multiple of the human's largest step so far, > 0.
    floor : float
        The smallest limit, mm/s per tick, >= 0 (so that ``v_a`` can move before the human does).

    Notes
    -----
    Bad data policy: a non-finite ``v`` passes to ``v_a`` (the position then holds) and the next finite one is
    followed from the last finite output; a non-finite ``v_h`` leaves the human's largest step as it was.
    """

    def __init__(self, factor: float = 1.0, floor: float = 1.0, *, period: float | None = None) -> None:
        super().__init__(period=period)
        self.factor = finite_number(self, "factor", factor, low=0.0, low_open=True)
        self.floor = finite_number(self, "floor", floor, low=0.0)
        self.add_input("v", VELOCITY)
        self.add_input("v_h", VELOCITY)
        self.add_output("v_a", VELOCITY)
        self.add_state("last", np.zeros(3))
        self.add_state("last_h", np.zeros(3))
        self.add_state("largest", 0.0)
        self.add_state("started", False)

    def _limit(self) -> float:
        v_h = self.v_h.value
        largest = self.largest
        if self.started and np.all(np.isfinite(v_h)):
            largest = max(largest, float(np.linalg.norm(v_h - self.last_h)))
        return max(self.floor, self.factor * largest)

    def output(self, k: int) -> None:
        v, out = self.v.value, self.v_a.value
        if not self.started or not np.all(np.isfinite(v)):
            out[...] = v
            return
        step = v - self.last
        size = float(np.linalg.norm(step))
        limit = self._limit()
        if size > limit:
            step *= limit / size
        np.add(self.last, step, out=out)

    def update(self, k: int) -> None:
        v_h = self.v_h.value
        if np.all(np.isfinite(v_h)):
            if self.started:
                self.largest = max(self.largest, float(np.linalg.norm(v_h - self.last_h)))
            self.last_h[...] = v_h
        if np.all(np.isfinite(self.v_a.value)):
            self.last[...] = self.v_a.value
            self.started = True
