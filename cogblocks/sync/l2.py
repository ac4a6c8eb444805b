"""The L2 architecture of the PoP of Social Connectedness as one block: motion computer and blender."""

from __future__ import annotations

from cogblocks.blocks import Select
from cogblocks.sim import Block, Diagram
from cogblocks.sim.params import block_with_ports, positive_int
from cogblocks.sync.blender import Blender
from cogblocks.sync.blending import BlenderParams

__all__ = ["L2Sync"]


class L2Sync(Diagram):
    """The L2 cognitive architecture of the PoP of Social Connectedness, as one block.

    ``theta`` (all participants' phases) → the assisted participant's phase
    θ_L0 and a motion computer's θ_ref → :class:`~cogblocks.sync.Blender` →
    θ_L2. The motion computer also sees the blender's λ.

    Ports
    -----
    theta : input, shape (N,), rad, wrapped
    theta_l2 : output, the avatar's phase
    theta_l0, theta_ref, lam : outputs, for looking inside

    Parameters
    ----------
    motion : Block
        A motion computer (ports ``theta``, ``lam`` → ``theta_ref``), e.g.
        :class:`~cogblocks.sync.MeanPhaseMotion` (the role: :class:`~cogblocks.sync.MotionComputer`).
    assisted : int
        0-based index of the assisted participant; the motion computer's own, if it has one.
    blender : Block, optional
        A blending rule with the ports of :class:`~cogblocks.sync.Blender` (``theta_l0``,
        ``theta_ref`` → ``theta_l2``, ``lam``); the deliverable's blender by default. Its
        ``params`` (a :class:`~cogblocks.sync.blending.BlenderParams`), if it has them, are handed
        to the motion computer's ``plan_through``: a motion computer that predicts plans through
        the blender actually in the diagram.

    Notes
    -----
    Bad data policy: that of the blocks inside. With the library's motion computers and
    blender a non-finite phase never reaches ``theta_l2``, ``theta_ref`` or ``lam`` (the
    motion computer leaves it out or coasts, the blender holds or passes θ_L0 unaltered);
    ``theta_l0``, the assisted participant's phase as given, shows it.
    """

    def __init__(self, motion: Block, assisted: int, blender: Block | None = None) -> None:
        super().__init__()
        block_with_ports(self, "motion", motion, inputs=("theta", "lam"), outputs=("theta_ref",))
        assisted = positive_int(self, "assisted", assisted, minimum=0)
        own = getattr(motion, "assisted", assisted)
        n = getattr(motion, "n", None)
        if own != assisted or (n is not None and assisted >= n):
            allowed = f"the motion computer's assisted index {own}" if own != assisted else f"an index below n = {n}"
            raise ValueError(f"L2Sync: assisted must be {allowed}, got {assisted!r}")
        if blender is not None:
            block_with_ports(self, "blender", blender, inputs=("theta_l0", "theta_ref"), outputs=("theta_l2", "lam"))
        select = self.add("select_l0", Select(assisted))
        self.add("motion", motion)
        blend = self.add("blender", blender if blender is not None else Blender())
        self.connect(select.y, blend.theta_l0)
        self.connect(motion.theta_ref, blend.theta_ref)
        self.connect(blend.lam, motion.lam)
        self.expose_input("theta", select.u, motion.theta)
        self.expose_output("theta_l2", blend.theta_l2)
        self.expose_output("theta_l0", select.y)
        self.expose_output("theta_ref", motion.theta_ref)
        self.expose_output("lam", blend.lam)
        self._hand_blender()

    def _changed(self) -> None:
        super()._changed()
        self._hand_blender()  # a motion computer or a blender swapped in by replace() is told too

    def _hand_blender(self) -> None:
        """Tell the motion computer the blender's parameters: one that predicts plans through the blender in use."""
        try:
            motion, blend = self["motion"], self["blender"]
        except KeyError:  # still being built
            return
        params = getattr(blend, "params", None)
        if isinstance(params, BlenderParams) and callable(getattr(motion, "plan_through", None)):
            motion.plan_through(params)
