"""A wrapper around any motion computer: its reference plays only while the group's own prediction errors say
the group is the deterministic model the motion computer bets on.

A planner (``replan``, ``guard``) bets that the identified deterministic model comes true to the end of the trial;
among people (phase noise, drifting frequencies, estimated phases) it does not, and the circular mean of the
others, which looks only at the present, holds up better. :class:`NoiseGate` identifies the group itself
(:class:`~cogblocks.sync.identification.KuramotoRLS`, as the planners do) from the phases the group saw, rebuilt
through the blender in the diagram (:meth:`NoiseGate.plan_through`), and measures the one-tick prediction errors its
best fit leaves: a deterministic Kuramoto group leaves none (the fit is exact to the rounding), a noisy one about
``σ √dt`` a tick (more with drift or estimated phases). From ``decide_after`` seconds on, every ``check_every``
seconds, it estimates ``σ̂`` from the residuals; once ``σ̂ > threshold`` it switches for good from the inner
motion computer's reference to the fallback's (the circular mean of the others, or doing nothing). It says which
world it believes it is in: :attr:`NoiseGate.world` and the ``noisy`` output. No knowledge of the noise is used;
the threshold only separates "exact" from "not exact".

:class:`GatedMotion` wires a motion computer, the fallback and the gate into one block with the motion computers'
ports (``theta``, ``lam`` in; ``theta_ref`` out), plus ``noisy``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from cogblocks.blocks.angles import wrap_angle, wrap_pi
from cogblocks.blocks.specs import PHASE
from cogblocks.sim import Block, Diagram, Signal
from cogblocks.sim.params import block_with_ports, finite_number, one_of, positive_int
from cogblocks.sync.blending import DELIVERABLE, BlenderParams, alteration
from cogblocks.sync.coupling import Coupling, checked_graph
from cogblocks.sync.identification import KuramotoRLS, usable_phases
from cogblocks.sync.motion import MeanPhaseMotion

__all__ = ["DECIDE_AFTER", "FALLBACKS", "GatedMotion", "NoiseGate", "THRESHOLD", "WORLDS"]

#: What the gate plays once the group is found noisy: the others' circular mean, or no alteration (θ_ref = θ_L0).
FALLBACKS = ("mean", "nothing")
#: What the gate believes: before its first decision, the model's world (the inner motion computer plays), the noisy
#: world (the fallback plays, for good).
WORLDS = ("undecided", "model", "noisy")
#: Seconds of observation before the gate's first decision: 1 s and 2 s were tried on 16 noisy validation groups
#: (20 s each; docs/explanation/noisy-groups.md), 1 s kept (+3.12 % against +2.97 %; on noise-free groups the gate
#: plays the model either way, σ̂ being four orders of magnitude below the threshold at 1 s already).
DECIDE_AFTER = 1.0
#: σ̂ (rad/√s) above which a group counts as noisy: deterministic groups leave about 1e-8 (the rounding), the
#: noisy validation groups at least 0.1 (people's phase noise is 0.05–0.5 rad/√s, docs/explanation/noisy-groups.md).
THRESHOLD = 0.02


class NoiseGate(Block):
    """Passes the inner motion computer's reference until its own residuals say the group is noisy, then the
    fallback's.

    Ports
    -----
    theta : input, shape (N,), rad, wrapped
        The participants' phases (as every motion computer sees them).
    lam : input, scalar, rad
        The blender's threshold (to rebuild the phase the group saw for the assisted participant).
    ref_model, ref_fallback : input, scalar, rad, wrapped
        The inner motion computer's and the fallback's references of this tick (``ref_fallback`` unused with
        ``fallback="nothing"``).
    theta_ref : output, scalar, rad, wrapped
        ``ref_model`` in the model's world, the fallback's reference in the noisy world.
    noisy : output, scalar
        1 once the group is found noisy, else 0.

    Parameters
    ----------
    n, assisted, adjacency : as every identifying motion computer
    fallback : {"mean", "nothing"}
        What plays in the noisy world: ``ref_fallback`` (the circular mean, in :class:`GatedMotion`), or θ_L0.
    decide_after : float
        Seconds of observation before the first decision, > 0.
    check_every : float
        Seconds between decisions after the first, > 0 (a group found noisy stays so).
    threshold : float
        σ̂ (rad/√s) above which the group counts as noisy, >= 0.
    blender : BlenderParams, optional
        The blender the phases seen are rebuilt through; in a diagram, the one it sits behind (:meth:`plan_through`).
    period : float, optional
        Block period.

    Attributes
    ----------
    world : {"undecided", "model", "noisy"}
        What the gate believes.
    sigma_hat : float
        The last estimate σ̂ (rad/√s; NaN before the first decision).

    Notes
    -----
    ``σ̂² = SSR · dt / (m N − N − 1)`` over the m ticks identified (SSR: the fit's residual sum of squares of the
    rates). Bad data policy: a tick with unusable phases adds nothing (as in the identification), and a non-finite
    reference holds the last ``theta_ref``.
    """

    def __init__(
        self,
        n: int,
        assisted: int,
        *,
        adjacency: Any = "ring",
        fallback: str = "mean",
        decide_after: float = DECIDE_AFTER,
        check_every: float = 1.0,
        threshold: float = THRESHOLD,
        blender: BlenderParams | None = None,
        period: float | None = None,
    ) -> None:
        super().__init__(period=period)
        self.n = positive_int(self, "n", n, minimum=2)
        if isinstance(assisted, bool) or not isinstance(assisted, (int, np.integer)) or not 0 <= assisted < self.n:
            raise ValueError(f"NoiseGate: assisted must be a 0-based index in [0, {self.n - 1}], got {assisted!r}")
        self.assisted = int(assisted)
        self.fallback = one_of(self, "fallback", fallback, FALLBACKS)
        self.decide_after = finite_number(self, "decide_after", decide_after, low=0.0, low_open=True)
        self.check_every = finite_number(self, "check_every", check_every, low=0.0, low_open=True)
        self.threshold = finite_number(self, "threshold", threshold, low=0.0)
        if blender is not None and not isinstance(blender, BlenderParams):
            raise ValueError(f"NoiseGate: blender must be a BlenderParams or None, got {type(blender).__name__}")
        self.blender = DELIVERABLE if blender is None else blender
        graph = Coupling(checked_graph(self, adjacency, self.n), self.n, sparse=False).matrix
        self.rls = KuramotoRLS(np.asarray(graph, dtype=float))
        # θ_L0 passes straight through with fallback="nothing": theta is feedthrough, as the mean's
        self.add_input("theta", PHASE.with_(shape=(self.n,)))
        self.add_input("lam", Signal(unit="rad"), default=math.pi, feedthrough=False)
        self.add_input("ref_model", PHASE)
        self.add_input("ref_fallback", PHASE, default=math.nan)
        self.add_output("theta_ref", PHASE)
        self.add_output("noisy", Signal(unit="1"), initial=0.0)
        self.add_state("info", self.rls.info)
        self.add_state("rhs", self.rls.rhs)
        self.add_state("count", 0)
        self.add_state("previous", np.full(2 * self.n, math.nan))  # seen and own phases of the tick before
        self.add_state("squares", 0.0)  # Σ rate² over the identified ticks
        self.add_state("shift", 0.0)  # the blender's alteration of the last tick, as its law gives it
        self.add_state("next_check", self.decide_after)  # seconds from the first tick
        self.add_state("world_index", 0)  # into WORLDS
        self.add_state("sigma_hat", math.nan)

    def plan_through(self, blender: BlenderParams) -> None:
        """Rebuild the phases the group saw through ``blender``, the blender in the diagram."""
        self.blender = blender

    @property
    def world(self) -> str:
        """``"undecided"`` before the first decision, then ``"model"`` or ``"noisy"``."""
        return WORLDS[self.world_index]

    def _reference(self) -> float:
        if self.world_index < 2:
            return float(self.ref_model.value)
        if self.fallback == "mean":
            return float(self.ref_fallback.value)
        return float(self.theta.value[self.assisted])

    def output(self, k: int) -> None:
        ref = self._reference()
        if math.isfinite(ref):
            self.theta_ref.value[...] = wrap_angle(ref)
        self.noisy.value[...] = 1.0 if self.world_index == 2 else 0.0

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
        if math.isfinite(lam) and math.isfinite(ref) and math.isfinite(l0):
            # the blender's own law and memory: what it made of this tick's reference
            self.shift = float(alteration(float(wrap_pi(ref - l0)), lam, self.blender, self.shift, self.dt))
            seen[self.assisted] = wrap_angle(l0 + self.shift)
        good = usable_phases(seen)
        self.previous[:n], self.previous[n:] = (seen, theta) if good else (math.nan, math.nan)
        if self.world_index < 2 and (k + 1) * self.dt >= self.next_check - 1e-9:
            self.sigma_hat = self.residual_sigma(dt)
            if math.isfinite(self.sigma_hat):
                self.world_index = 2 if self.sigma_hat > self.threshold else 1
            self.next_check += self.check_every

    def residual_sigma(self, dt: float) -> float:
        """σ̂ (rad/√s) from the fit's residuals so far (NaN before there are more equations than unknowns)."""
        dof = self.count * self.n - self.n - 1
        if dof <= 0:
            return math.nan
        x = np.linalg.solve(self.info, self.rhs)
        # Σ (y − Hx)² from the information form, the prior's pull (weight w toward p) taken out:
        # HᵀH x = rhs − w x, Hᵀy = rhs − w p
        w, p = self.rls.prior_weight, self.rls.prior
        ssr = self.squares - float(x @ self.rhs) + w * float(x @ (2.0 * p - x))
        return math.sqrt(max(0.0, ssr) * dt / dof)


class _Idle(Block):
    """Passes the phases to the inner motion computer until the gate's ``noisy`` output says the fallback plays for
    good, then NaN: every motion computer's bad data policy ignores a non-finite phase, so a planner stops deciding
    (and spending CPU) once its reference is no longer played. ``noisy`` is read in :meth:`update` (the gate's
    outputs depend on the model's): the phases stop one tick after the switch."""

    def __init__(self, n: int) -> None:
        super().__init__()
        self.add_input("theta", PHASE.with_(shape=(n,)))
        self.add_input("noisy", Signal(unit="1"), feedthrough=False)
        self.add_output("theta_model", PHASE.with_(shape=(n,)))
        self.add_state("idle", False)

    def output(self, k: int) -> None:
        self.theta_model.value[...] = math.nan if self.idle else self.theta.value

    def update(self, k: int) -> None:
        self.idle = self.idle or float(self.noisy.value) == 1.0


class GatedMotion(Diagram):
    """A motion computer behind a :class:`NoiseGate`: its reference while the group behaves as the model, then the
    fallback's. One block with the motion computers' ports and ``noisy``.

    Blocks: ``model`` (the motion computer given), ``fallback`` (a :class:`~cogblocks.sync.MeanPhaseMotion`, with
    ``fallback="mean"``), ``gate``, and ``idle``, which feeds the model the phases until the fallback plays for good
    and NaN from the next tick on (the model's bad data policy then leaves it idle: a planner stops deciding, so a
    gated planner costs little more than the fallback among noise).

    Ports
    -----
    theta : input, shape (N,), rad, wrapped
    lam : input, scalar, rad
    theta_ref : output, scalar, rad, wrapped
    noisy : output, scalar (1 once the group is found noisy)

    Parameters
    ----------
    model : Block
        Any motion computer (ports ``theta``, ``lam`` → ``theta_ref``).
    n, assisted : int, optional
        The group's size and the assisted participant (0-based); the model's own ``n`` and ``assisted`` by default.
    adjacency : graph spec, optional
        The group's graph, known to the gate; the model's ``adjacency`` (an identifying motion computer's matrix)
        by default.
    fallback, decide_after, check_every, threshold :
        The gate's (:class:`NoiseGate`).

    Attributes
    ----------
    world : {"undecided", "model", "noisy"}
        What the gate believes (:attr:`NoiseGate.world`).
    sigma_hat : float
        The gate's last σ̂ (rad/√s).

    Notes
    -----
    The blender's parameters handed to the block (:meth:`plan_through`, which :class:`~cogblocks.sync.L2Sync`
    calls) reach the model and the gate. Bad data policy: that of the blocks inside.
    """

    def __init__(
        self,
        model: Block,
        *,
        n: int | None = None,
        assisted: int | None = None,
        adjacency: Any = None,
        fallback: str = "mean",
        decide_after: float = DECIDE_AFTER,
        check_every: float = 1.0,
        threshold: float = THRESHOLD,
    ) -> None:
        super().__init__()
        block_with_ports(self, "model", model, inputs=("theta", "lam"), outputs=("theta_ref",))
        for name, given in (("n", n), ("assisted", assisted)):
            own = getattr(model, name, None)
            if given is not None and own is not None and given != own:
                raise ValueError(f"GatedMotion: {name} must be the model's {name} = {own}, got {given!r}")
        n = getattr(model, "n", None) if n is None else n
        assisted = getattr(model, "assisted", None) if assisted is None else assisted
        if n is None or assisted is None:
            raise ValueError(f"GatedMotion: give n and assisted for a model without them ({type(model).__name__})")
        if adjacency is None:
            adjacency = getattr(model, "adjacency", None)
            if not isinstance(adjacency, np.ndarray):
                raise ValueError(
                    f"GatedMotion: adjacency must be given for a model that does not hold the graph "
                    f"({type(model).__name__})"
                )
        gate = NoiseGate(
            n,
            assisted,
            adjacency=adjacency,
            fallback=fallback,
            decide_after=decide_after,
            check_every=check_every,
            threshold=threshold,
        )
        self.n, self.assisted = gate.n, gate.assisted
        self._blender: BlenderParams | None = None
        idle = self.add("idle", _Idle(gate.n))
        self.add("model", model)
        self.add("gate", gate)
        self.connect(idle.theta_model, model.theta)
        self.connect(gate.noisy, idle.noisy)
        self.connect(model.theta_ref, gate.ref_model)
        inputs: dict[str, list[Any]] = {"theta": [idle.theta, gate.theta], "lam": [model.lam, gate.lam]}
        if fallback == "mean":
            mean = self.add("fallback", MeanPhaseMotion(n, assisted))
            self.connect(mean.theta_ref, gate.ref_fallback)
            inputs["theta"].append(mean.theta)
            inputs["lam"].append(mean.lam)
        self.expose_input("theta", *inputs["theta"])
        self.expose_input("lam", *inputs["lam"])
        self.expose_output("theta_ref", gate.theta_ref)
        self.expose_output("noisy", gate.noisy)

    @property
    def decision_period(self) -> float | None:
        """The model's decision period (s; ``None``: every tick)."""
        return getattr(self["model"], "decision_period", None)

    @property
    def world(self) -> str:
        """What the gate believes: ``"undecided"``, ``"model"`` or ``"noisy"``."""
        return self["gate"].world

    @property
    def sigma_hat(self) -> float:
        """The gate's last σ̂ (rad/√s; NaN before its first decision)."""
        return self["gate"].sigma_hat

    def plan_through(self, blender: BlenderParams) -> None:
        """Hand ``blender`` (the diagram's blender) to the model, if it predicts, and to the gate."""
        self._blender = blender
        for name in ("model", "gate"):
            block = self[name]
            if callable(getattr(block, "plan_through", None)):
                block.plan_through(blender)

    def _changed(self) -> None:
        super()._changed()
        if getattr(self, "_blender", None) is not None and "gate" in self:
            self.plan_through(self._blender)  # a model swapped in by replace() plans through the blender too
