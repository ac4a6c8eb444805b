"""The L2 architecture of the PoP of Amplification as one block."""

from __future__ import annotations

from typing import Any

from cogblocks.amplification.blending import BLENDING_INPUTS, BLENDING_OUTPUTS, VelocityBlender
from cogblocks.amplification.buffer import Buffer
from cogblocks.amplification.corrector import NoCorrection
from cogblocks.amplification.position import VelocityPositionComputer
from cogblocks.amplification.projector import LibraryProjector
from cogblocks.amplification.smoothing import VelocityStepLimiter
from cogblocks.amplification.solution import SolutionTable
from cogblocks.data.reach import ReachLibrary
from cogblocks.sim import Block, Diagram
from cogblocks.sim.params import block_with_ports, finite_number, one_of, positive_int

__all__ = ["L2Amplification"]


class L2Amplification(Diagram):
    """The L2 architecture of the PoP of Amplification, as one block.

    ``v_h, p_h`` → :class:`~cogblocks.amplification.Buffer` (``buffer``) →
    :class:`~cogblocks.amplification.LibraryProjector` (``projector``) → blending rule
    (``blender``, a :class:`~cogblocks.amplification.VelocityBlender` by default) →
    :class:`~cogblocks.amplification.VelocityPositionComputer` (``position``); the corrector
    (``corrector``) sees positions and velocities and adds ``v_u`` to the blend. The corrector and
    the blending rule can be swapped with :meth:`~cogblocks.sim.Diagram.replace` for any block with
    the same ports.

    Ports
    -----
    v_h : input, shape (3,), mm/s
    p_h : input, shape (3,), mm
    v_a, p_a : outputs, the altered velocity and position
    c : output, the blending coefficient
    v_r : output, the reference velocity
    v_u, alpha : outputs, the correction and the corrector's action
    nearest, reference : outputs, library indices of η_i and of the reference (−1 before the first decision)

    Parameters
    ----------
    library : ReachLibrary
        The movement library searched by the projector.
    table : SolutionTable
        w̃ on ``library`` for ``e_des`` (used by the default blender).
    corrector : Block, optional
        :class:`~cogblocks.amplification.NoCorrection` by default, or an
        :class:`~cogblocks.amplification.RLCorrector`.
    blending : Block, optional
        A blending rule with the ports of :class:`~cogblocks.amplification.VelocityBlender`.
    e_des : {0, 1}
        1 encodes fear, 0 removes it (the fear and no-fear sets swap roles).
    interval : int
        ΔT, samples between two decisions (at most ``capacity``).
    capacity : int
        Samples kept by the buffer.
    step_limit : float, optional
        Put a :class:`~cogblocks.amplification.smoothing.VelocityStepLimiter` (``limiter``) after the blending
        rule, its ``factor`` this value: the altered velocity's per-tick step stays within ``step_limit`` × the
        human's largest step so far. ``None`` (default): the rule's velocity as it is.
    candidates : array_like of bool, optional
        Library movements the projector may choose, as in
        :class:`~cogblocks.amplification.LibraryProjector`.

    Notes
    -----
    Bad data policy: that of the blocks inside. The buffer stores a non-finite or implausible
    sample as the last good one, so the search and the corrector never see it; the blend passes a
    non-finite ``v_h`` to ``v_a`` on that tick, and the position then holds.
    """

    def __init__(
        self,
        library: ReachLibrary,
        table: SolutionTable,
        *,
        corrector: Block | None = None,
        blending: Block | None = None,
        e_des: int = 1,
        interval: int = 10,
        capacity: int = 200,
        candidates: Any = None,
        step_limit: float | None = None,
    ) -> None:
        super().__init__()
        if not isinstance(library, ReachLibrary):
            raise ValueError(f"L2Amplification: library must be a ReachLibrary, got {type(library).__name__}")
        e_des = one_of(self, "e_des", e_des, (0, 1))
        if not isinstance(table, SolutionTable) or table.e_des != e_des:
            raise ValueError(
                f"L2Amplification: table must be a SolutionTable for e_des={e_des}, "
                f"got {type(table).__name__} for e_des={getattr(table, 'e_des', None)}"
            )
        capacity = positive_int(self, "capacity", capacity)
        interval = positive_int(self, "interval", interval)
        if interval > capacity:
            raise ValueError(
                f"L2Amplification: interval must be an integer in [1, capacity={capacity}], got {interval}"
            )
        if blending is not None:
            block_with_ports(
                self,
                "blending",
                blending,
                inputs=BLENDING_INPUTS,
                outputs=BLENDING_OUTPUTS,
            )
        if corrector is not None:
            block_with_ports(
                self, "corrector", corrector, inputs=("p_h", "p_a", "v_h", "v_a", "horizon"), outputs=("v_u", "alpha")
            )
        buffer = self.add("buffer", Buffer(capacity))
        projector = self.add(
            "projector", LibraryProjector(library, e_des=e_des, interval=interval, candidates=candidates)
        )
        blender = self.add("blender", blending if blending is not None else VelocityBlender(table))
        fix = self.add("corrector", corrector if corrector is not None else NoCorrection())
        position = self.add("position", VelocityPositionComputer())
        self.connect(buffer.velocity, projector.velocity)
        self.connect(buffer.count, projector.count)
        for port in ("v_r", "nearest", "reference", "decisions"):
            self.connect(f"projector.{port}", f"blender.{port}")
        self.connect(projector.horizon, fix.horizon)
        self.connect(fix.v_u, blender.v_u)
        altered, human = blender.v_a, [buffer.v, blender.v_h, fix.v_h]
        if step_limit is not None:  # between the rule and everything that reads the altered velocity
            step_limit = finite_number(self, "step_limit", step_limit, low=0.0, low_open=True)
            limiter = self.add("limiter", VelocityStepLimiter(step_limit))
            self.connect(blender.v_a, limiter.v)
            altered = limiter.v_a
            human.append(limiter.v_h)
        self.connect(altered, position.v, fix.v_a)
        self.connect(position.p, fix.p_a)
        self.expose_input("v_h", *human)
        self.expose_input("p_h", buffer.p, position.p_start, fix.p_h)
        self.expose_output("v_a", altered)
        self.expose_output("p_a", position.p)
        self.expose_output("c", blender.c)
        self.expose_output("v_r", projector.v_r)
        self.expose_output("v_u", fix.v_u)
        self.expose_output("alpha", fix.alpha)
        self.expose_output("nearest", projector.nearest)
        self.expose_output("reference", projector.reference)
