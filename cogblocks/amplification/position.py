"""Position by integration of the altered velocity: p_a(t+1) = p_a(t) + dt·v_a(t+1)."""

from __future__ import annotations

import numpy as np

from cogblocks.blocks.samples import plausible
from cogblocks.blocks.specs import POSITION, VELOCITY
from cogblocks.sim import Block

__all__ = ["VelocityPositionComputer"]


class VelocityPositionComputer(Block):
    """Position of the altered movement by integration: ``p_a(t+1) = p_a(t) + dt·v_a(t+1)``, ``p_a(1) = p_h(1)``.

    The update uses the velocity of the new sample, as in the notes; on data that follow eq. (1)
    (``v(t) = (p(t+1) − p(t)) / dt``) the integrated position of an unaltered movement is therefore
    one sample ahead of the recorded one while it moves, and equal to it at rest.

    Ports
    -----
    v : input, shape (3,), mm/s
        The altered velocity v_a.
    p_start : input, shape (3,), mm
        The human position; only its first finite sample is used.
    p : output, shape (3,), mm
        The altered position p_a.

    Notes
    -----
    This is the Amplification position block; the phase-to-position block of section 6.2 is
    :class:`cogblocks.phase.PhasePositionComputer`.

    Bad data policy: a non-finite or implausible (beyond 1 km/s,
    :func:`~cogblocks.blocks.samples.plausible`) velocity holds the position; integration starts
    at the first ``p_start`` that is finite and plausible.
    """

    def __init__(self, *, period: float | None = None) -> None:
        super().__init__(period=period)
        self.add_input("v", VELOCITY)
        self.add_input("p_start", POSITION)
        self.add_output("p", POSITION)
        self.add_state("last", np.zeros(3))
        self.add_state("started", False)

    def output(self, k: int) -> None:
        p = self.p.value
        if not self.started:
            if plausible(self.p_start.value):
                p[...] = self.p_start.value
        elif plausible(self.v.value):
            np.multiply(self.dt, self.v.value, out=p)
            p += self.last
        else:
            p[...] = self.last

    def update(self, k: int) -> None:
        if self.started or plausible(self.p_start.value):
            self.last[...] = self.p.value
            self.started = True
