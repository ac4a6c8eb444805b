"""The avatar shows the person's own movement until the phase estimate has settled, then the L2's phase.

On estimated phases the L2 architecture's θ_L2 is θ̂_L0 plus the alteration. Over a movement's first one to two
periods θ̂_L0 rests on provisional amplitudes and an unknown frequency (see
:class:`~cogblocks.phase.Algorithm1Phase`'s ``settled``): it is up to 2 rad off and steps by as much in one tick,
and an avatar drawn from it jumps and shows a phase the person does not have. A motion-capture avatar can
instead show the tracked movement itself until then. :class:`SettledHandover` does that, then hands over to
θ_L2 without a jump: its offset from the person's phase moves toward θ_L2's at most ``slew`` rad/s, and from the
tick it has reached it the avatar is θ_L2 for good.
"""

from __future__ import annotations

import math

import numpy as np

from cogblocks.blocks.angles import wrap_angle, wrap_pi
from cogblocks.blocks.specs import FLAG, PHASE
from cogblocks.sim import Block
from cogblocks.sim.params import finite_number, positive_int
from cogblocks.sync.blending import SLEW

__all__ = ["SettledHandover"]

#: Modes: the person's movement, the hand-over in progress, the L2's phase.
MIRROR, HANDING_OVER, FOLLOW = 0, 1, 2


class SettledHandover(Block):
    """The avatar's phase: the person's until the estimate has settled, then a slewed hand-over to θ_L2.

    Ports
    -----
    theta : input, shape (n,), rad, wrapped
        The participants' phases as the avatar's own tracking shows them (in a simulation, the group's).
    theta_l2 : input, scalar, rad, wrapped
        The L2 architecture's phase.
    settled : input, shape (n,), bool
        Whether each participant's phase estimate has settled; the assisted participant's is read.
    theta_avatar : output, scalar, rad, wrapped
        The phase the avatar shows.

    Parameters
    ----------
    n : int
        Number of participants.
    assisted : int
        Index of the assisted participant.
    slew : float
        Largest rate (rad/s) at which the hand-over moves the avatar off the person's phase (the continuous
        blender's, so that the hand-over steps no harder than an alteration).

    Notes
    -----
    Once the assisted participant's estimate has settled the hand-over starts and never goes back (the estimate
    stays settled through drop-outs, which it bridges). Bad data policy: a non-finite ``theta_l2`` or assisted
    phase holds the last output and advances nothing.
    """

    def __init__(self, n: int, assisted: int, *, slew: float = SLEW, period: float | None = None) -> None:
        super().__init__(period=period)
        self.n = positive_int(self, "n", n)
        if isinstance(assisted, bool) or not isinstance(assisted, (int, np.integer)) or not 0 <= assisted < self.n:
            raise ValueError(
                f"SettledHandover: assisted must be a 0-based index in [0, {self.n - 1}], got {assisted!r}"
            )
        self.assisted = int(assisted)
        self.slew = finite_number(self, "slew", slew, low=0.0, low_open=True)
        self.add_input("theta", PHASE.with_(shape=(self.n,)))
        self.add_input("theta_l2", PHASE)
        self.add_input("settled", FLAG.with_(shape=(self.n,)))
        self.add_output("theta_avatar", PHASE)
        self.add_state("mode", MIRROR)
        self.add_state("offset", 0.0)  # the avatar's phase minus the person's, during the hand-over
        self.add_scratch("_next", None)  # (mode, offset) that output computed and update commits

    def output(self, k: int) -> None:
        person = float(self.theta.value[self.assisted])
        theta_l2 = float(self.theta_l2.value)
        self._next = None
        if not (math.isfinite(person) and math.isfinite(theta_l2)):
            return
        mode, offset = self.mode, self.offset
        if mode == MIRROR and bool(self.settled.value[self.assisted]):
            mode = HANDING_OVER
        if mode == HANDING_OVER:
            gap = wrap_pi(theta_l2 - person - offset)  # the offset itself is not wrapped: it moves on a line
            step = self.slew * self.dt
            if abs(gap) <= step:
                mode = FOLLOW
            else:
                offset += math.copysign(step, gap)
        if mode == FOLLOW:
            shown = wrap_angle(theta_l2)
        else:
            shown = wrap_angle(person + offset)
        self.theta_avatar.value[...] = shown
        self._next = (mode, offset)

    def update(self, k: int) -> None:
        if self._next is not None:
            self.mode, self.offset = self._next
