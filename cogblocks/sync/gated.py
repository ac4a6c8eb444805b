"""A motion computer that recognises from its own prediction errors whether the group is the model it plans on.

A planner (``replan``, ``guard``) bets that the identified deterministic model comes true to the end of the trial;
among people (phase noise, drifting frequencies, estimated phases) it does not, and the circular mean of the
others, which looks only at the present, holds up better. :class:`NoiseGate` identifies the group itself
(:class:`~cogblocks.sync.identification.KuramotoRLS`, as the planners do) and measures the one-tick prediction
errors its best fit leaves: a deterministic Kuramoto group leaves none (the fit is exact to the rounding), a noisy
one leaves ``σ √dt`` a tick (more with drift). At ``decide_after`` seconds it estimates ``σ̂`` from the residuals
and, if ``σ̂ > threshold``, switches for good from the planner's reference to the fallback's (``noisy`` output 1:
the block says which world it believes it is in). Before that, the planner plays. No knowledge of the noise is
used; the threshold only separates "exact" from "not exact".

:func:`noise_gated` wires a planner, :class:`~cogblocks.sync.motion.MeanPhaseMotion` and the gate into one block
with the motion computers' ports (``theta``, ``lam`` in; ``theta_ref`` out), plus ``noisy``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from cogblocks.blocks.angles import wrap_angle, wrap_pi
from cogblocks.blocks.specs import PHASE
from cogblocks.sim import Block, Diagram, Signal
from cogblocks.sim.params import finite_number, positive_int
from cogblocks.sync.coupling import Coupling, checked_graph
from cogblocks.sync.identification import KuramotoRLS, usable_phases
from cogblocks.sync.motion import MeanPhaseMotion

__all__ = ["NoiseGate", "noise_gated"]


class NoiseGate(Block):
    """Passes the planner's reference until its own residuals say the group is noisy, then the fallback's.

    Ports
    -----
    theta : input, shape (N,), rad, wrapped
        The participants' phases (as every motion computer sees them).
    lam : input, scalar, rad
        The blender's threshold (to know the phase the group saw for the assisted participant).
    ref_model, ref_fallback : input, scalar, rad, wrapped
        The planner's and the fallback's references of this tick (feedthrough).
    theta_ref : output, scalar, rad, wrapped
        ``ref_model`` until the decision, then ``ref_fallback`` if the group was found noisy.
    noisy : output, scalar
        1 once the group is found noisy, else 0.

    Parameters
    ----------
    n, assisted, adjacency : as every identifying motion computer
    decide_after : float
        Seconds of observation before the one decision, > 0.
    threshold : float
        σ̂ (rad/√s) above which the group counts as noisy, >= 0.
    period : float, optional
        Block period.

    Notes
    -----
    ``σ̂² = SSR · dt / (m N − N − 1)`` over the m ticks identified (SSR: the fit's residual sum of squares of the
    rates). Bad data policy: a tick with unusable phases adds nothing (as in the identification).
    """

    def __init__(
        self,
        n: int,
        assisted: int,
        *,
        adjacency: Any = "ring",
        decide_after: float = 2.0,
        threshold: float = 0.02,
        period: float | None = None,
    ) -> None:
        super().__init__(period=period)
        self.n = positive_int(self, "n", n, minimum=2)
        if isinstance(assisted, bool) or not isinstance(assisted, (int, np.integer)) or not 0 <= assisted < self.n:
            raise ValueError(f"NoiseGate: assisted must be a 0-based index in [0, {self.n - 1}], got {assisted!r}")
        self.assisted = int(assisted)
        graph = Coupling(checked_graph(self, adjacency, self.n), self.n, sparse=False).matrix
        self.rls = KuramotoRLS(np.asarray(graph, dtype=float))
        self.add_input("theta", PHASE.with_(shape=(self.n,)), feedthrough=False)
        self.add_input("lam", Signal(unit="rad"), default=math.pi, feedthrough=False)
        self.add_output("theta_ref", PHASE)
        self.add_state("info", self.rls.info)
        self.add_state("rhs", self.rls.rhs)
        self.add_state("count", 0)
        self.decide_after = finite_number(self, "decide_after", decide_after, low=0.0, low_open=True)
        self.threshold = finite_number(self, "threshold", threshold, low=0.0)
        self.add_input("ref_model", PHASE)
        self.add_input("ref_fallback", PHASE)
        self.add_output("noisy", Signal(unit="1"), initial=0.0)
        self.add_state("previous", np.full(2 * self.n, math.nan))  # seen and own phases of the tick before
        self.add_state("squares", 0.0)  # Σ rate² over the identified ticks
        self.add_state("played", 0.0)  # the reference this block output last tick
        self.add_state("decided", False)
        self.add_state("sigma_hat", math.nan)

    def output(self, k: int) -> None:
        use_fallback = self.decided and self.noisy_now()
        ref = float((self.ref_fallback if use_fallback else self.ref_model).value)
        if math.isfinite(ref):
            self.theta_ref.value[...] = ref
        self.noisy.value[...] = 1.0 if use_fallback else 0.0

    def noisy_now(self) -> bool:
        """Whether the decision taken says the group is noisy."""
        return bool(self.decided and self.sigma_hat > self.threshold)

    def update(self, k: int) -> None:
        theta = np.asarray(self.theta.value, dtype=float)
        lam = float(self.lam.value)
        dt = self.dt * self.every
        n, rls = self.n, self.rls
        rls.info, rls.rhs = self.info, self.rhs  # the declared state, so that snapshots and reset cover it
        if usable_phases(self.previous) and rls.observe(self.previous[:n], self.previous[n:], theta, dt):
            self.count += 1
            self.squares += float(np.sum((wrap_pi(theta - self.previous[n:]) / dt) ** 2))
        l0, ref = float(theta[self.assisted]), float(self.theta_ref.value)
        seen = theta.copy()
        if math.isfinite(lam) and math.isfinite(ref):
            seen[self.assisted] = wrap_angle(l0 + min(max(float(wrap_pi(ref - l0)), -lam), lam))
        good = usable_phases(seen)
        self.previous[:n], self.previous[n:] = (seen, theta) if good else (math.nan, math.nan)
        if not self.decided and (k + 1) * self.dt >= self.decide_after:
            self.sigma_hat = self.residual_sigma(dt)
            self.decided = True

    def residual_sigma(self, dt: float) -> float:
        """σ̂ (rad/√s) from the fit's residuals so far (NaN before there are more equations than unknowns)."""
        dof = self.count * self.n - self.n - 1
        if dof <= 0:
            return math.nan
        x = np.linalg.solve(self.info, self.rhs)
        ssr = max(0.0, self.squares - float(self.rhs @ x))
        return math.sqrt(ssr * dt / dof)


def noise_gated(
    model: Block,
    n: int,
    assisted: int,
    *,
    adjacency: Any = "ring",
    decide_after: float = 2.0,
    threshold: float = 0.02,
) -> Diagram:
    """A planner ``model`` (a motion computer block) behind a :class:`NoiseGate` that falls back to the circular
    mean on a noisy group: one block with the motion computers' ports and ``noisy``."""
    d = Diagram()
    planner = d.add("model", model)
    fallback = d.add("fallback", MeanPhaseMotion(n, assisted))
    gate = d.add("gate", NoiseGate(n, assisted, adjacency=adjacency, decide_after=decide_after, threshold=threshold))
    d.connect(planner.theta_ref, gate.ref_model)
    d.connect(fallback.theta_ref, gate.ref_fallback)
    d.expose_input("theta", planner.theta, fallback.theta, gate.theta)
    d.expose_input("lam", planner.lam, fallback.lam, gate.lam)
    d.expose_output("theta_ref", gate.theta_ref)
    d.expose_output("noisy", gate.noisy)
    return d
