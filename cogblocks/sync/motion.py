"""Motion computers: the reference phase θ_ref that the L2 blender pulls toward (section 5.2.2, Figure 4).

:class:`MotionComputer` is the role, the ports every motion computer has, so that one can replace another in a
diagram. :class:`OscillatorMotion` is the deliverable's L3 reference: a virtual Kuramoto oscillator at the assisted
participant's node whose frequency a policy nudges every tick. :class:`MeanPhaseMotion` is the simplest
alternative: the circular mean of the others' phases."""

from __future__ import annotations

import copy
import math
import warnings
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from cogblocks.blocks.angles import wrap_angle
from cogblocks.blocks.specs import PHASE
from cogblocks.sim import Block, Signal
from cogblocks.sim.params import finite_number, positive_int
from cogblocks.sync.blending import BlenderParams, blender_params
from cogblocks.sync.coupling import Coupling, checked_graph
from cogblocks.sync.identification import KuramotoRLS

__all__ = [
    "ACTIONS",
    "HOLD_ACTION",
    "L3Context",
    "L3Policy",
    "MeanPhaseMotion",
    "MotionComputer",
    "OMEGA_L3_LIMIT",
    "OscillatorMotion",
    "l3_observation",
]

#: Frequency increments (rad/s) an L3 policy chooses from (footnote 3 of the deliverable).
ACTIONS = np.round(np.arange(-0.5, 0.51, 0.1), 1)
#: Index of the action that keeps the frequency unchanged.
HOLD_ACTION = int(np.flatnonzero(ACTIONS == 0.0)[0])
#: Bound on the virtual oscillator's frequency, rad/s.
OMEGA_L3_LIMIT = 15.0


def l3_observation(theta_l3: Any, theta_others: np.ndarray, omega_prev: Any) -> np.ndarray:
    """The L3 policy's observation ``[angle(q), 1 − |q|, ω_prev]``.

    ``q = mean_j exp(i wrap_π(θ_L3 − θ_j))`` over the other participants: its angle is where the virtual
    oscillator sits relative to their circular mean, ``1 − |q|`` how spread they are. Broadcasts over leading axes.
    """
    offsets = np.asarray(theta_l3, dtype=float)[..., None] - theta_others
    # sum / n rather than mean(): the same value without mean()'s per-call overhead, which dominates here
    n = offsets.shape[-1]
    q_re = np.cos(offsets).sum(axis=-1) / n
    q_im = np.sin(offsets).sum(axis=-1) / n
    obs = np.empty(q_re.shape + (3,))
    obs[..., 0] = np.arctan2(q_im, q_re)
    obs[..., 1] = 1.0 - np.hypot(q_re, q_im)
    obs[..., 2] = omega_prev
    return obs


@dataclass(frozen=True, eq=False)
class L3Context:
    """What an L3 policy may use at tick ``k``.

    Attributes
    ----------
    k : int
        The tick.
    obs : ndarray, shape (3,)
        :func:`l3_observation` of this tick.
    theta : ndarray, shape (N,)
        The participants' own phases; ``theta[assisted]`` is θ_L0.
    theta_l3 : float
        Phase of the virtual oscillator, θ_ref of this tick.
    lam : float
        The blender's threshold λ of this tick.
    omega_prev : float
        The virtual oscillator's frequency at the previous tick.
    assisted : int or None
        0-based index of the assisted participant, if the caller knows it.
    """

    k: int
    obs: np.ndarray
    theta: np.ndarray
    theta_l3: float
    lam: float
    omega_prev: float
    assisted: int | None = None


class L3Policy(Protocol):
    """Chooses the frequency increment of the virtual oscillator, as an index into :data:`ACTIONS`."""

    def reset(self, omega_init: float) -> None:
        """Forget any episode memory; the oscillator restarts at ``omega_init``."""

    def act(self, context: L3Context) -> int:
        """The action index for this tick."""


class MotionComputer(Block):
    """The motion computer of the L2 architecture (Figure 4): the role every implementation plays.

    Ports
    -----
    theta : input, shape (N,), rad, wrapped
        The participants' own phases.
    lam : input, scalar, rad
        The blender's threshold λ of this tick (π when unconnected).
    theta_ref : output, scalar, rad, wrapped
        The reference the blender pulls the avatar toward.

    Parameters
    ----------
    n : int
        Number of participants (>= 2).
    assisted : int
        0-based index of the assisted participant.
    period : float, optional
        The block's own step (s); the diagram's by default.

    Notes
    -----
    Implementations: :class:`OscillatorMotion`, :class:`MeanPhaseMotion`, the planner
    :class:`~cogblocks.sync.receding.RecedingPlanMotion` (:func:`~cogblocks.sync.planned.whole_trial_plan` is its
    one-decision preset), :class:`~cogblocks.sync.mpc.MPCMotion`, and the shield
    :class:`~cogblocks.sync.shielded.ShieldedMotion` around any of them; ``cogblocks.diagrams.sync.MOTIONS``
    names their presets.
    ``MotionComputer(policy, n=..., ...)``, the name's earlier meaning, still builds an :class:`OscillatorMotion`,
    with a :class:`DeprecationWarning`; ``MotionComputer(n, assisted)`` is a block with the role's ports that
    holds θ_ref at 0.

    Bad data policy: the role's own block ignores its inputs; each implementation states its own policy.
    """

    def __new__(cls, *args: Any, **kwargs: Any) -> MotionComputer:
        # the old form: a policy first (anything but the role's n), or an oscillator's own keywords
        old_form = bool(args) and not isinstance(args[0], (int, np.integer))
        if cls is MotionComputer and (old_form or {"policy", "gain", "omega_init", "adjacency"} & kwargs.keys()):
            warnings.warn(
                "MotionComputer(policy, ...) is now OscillatorMotion(policy, ...); MotionComputer names the role",
                DeprecationWarning,
                stacklevel=2,
            )
            return super().__new__(OscillatorMotion, *args, **kwargs)
        return super().__new__(cls, *args, **kwargs)

    def __init__(self, n: int, assisted: int, period: float | None = None) -> None:
        super().__init__(period=period)
        n = positive_int(self, "n", n, minimum=2)
        if isinstance(assisted, bool) or not isinstance(assisted, (int, np.integer)) or not 0 <= assisted < n:
            raise ValueError(
                f"{type(self).__name__}: assisted must be a 0-based index in [0, {n - 1}], got {assisted!r}"
            )
        self.n, self.assisted = n, int(assisted)
        self.add_input("theta", PHASE.with_(shape=(n,)), feedthrough=self._theta_feedthrough)
        self.add_input("lam", Signal(unit="rad"), default=math.pi, feedthrough=False)
        self.add_output("theta_ref", PHASE)

    _theta_feedthrough = True

    @property
    def decision_period(self) -> float | None:
        """Seconds between the block's decisions; ``None``: it decides every tick."""
        return None

    def plan_through(self, blender: BlenderParams) -> None:
        """Take the parameters of the blender the block works behind (:class:`~cogblocks.sync.L2Sync` calls this);
        a motion computer that predicts through the blender plans with them, one that does not ignores them."""

    def predictor(self) -> MotionComputer:
        """A copy, outside any diagram, that a prediction runs ahead on predicted phases (a deep copy by default;
        an implementation may return a cheaper equivalent)."""
        return copy.deepcopy(self, {id(self._parent): None})


class _IdentifyingMotion(MotionComputer):
    """The ports, and what every motion computer that identifies the group online shares.

    ``adjacency`` (a graph spec) becomes the dense matrix the models run on, ``blender`` (a
    :class:`~cogblocks.sync.blending.BlenderParams` or a name of ``BLENDERS``, the deliverable's by default; in a
    diagram, the blender it sits behind: :meth:`plan_through`) the blender they plan through,
    and :class:`~cogblocks.sync.identification.KuramotoRLS` the identifier, whose sums ``info`` and ``rhs`` and
    count of increments ``count`` are block state, so that a snapshot holds what has been identified.
    """

    def __init__(
        self, n: int, assisted: int, period: float | None, adjacency: Any, blender: Any, forgetting: float = 1.0
    ) -> None:
        super().__init__(n, assisted, period)
        coupling = Coupling(checked_graph(self, adjacency, self.n), self.n, sparse=False)
        self.adjacency = np.asarray(coupling.matrix, dtype=float)
        self._blender_given = blender is not None
        self.blender: BlenderParams = blender_params(type(self).__name__, blender)
        self.rls = KuramotoRLS(self.adjacency, forgetting=forgetting)
        self.add_state("count", 0)  # increments identified
        self.add_state("info", self.rls.info)
        self.add_state("rhs", self.rls.rhs)

    def plan_through(self, blender: BlenderParams) -> None:
        """Plan through ``blender``, the blender in the diagram; refused if the block was built with another."""
        if self._blender_given and blender != self.blender:
            raise ValueError(
                f"{type(self).__name__}: built to plan through {self.blender}, but the diagram's blender is {blender}; "
                "leave the motion computer's blender out and the diagram hands it the one it has"
            )
        self.blender = blender

    def identifier(self) -> KuramotoRLS:
        """The identifier, on this tick's state (a restored snapshot replaces the state's arrays)."""
        self.rls.info, self.rls.rhs = self.info, self.rhs
        return self.rls


class MeanPhaseMotion(MotionComputer):
    """θ_ref is the circular mean of the other participants' phases.

    Needs no training and no model. A natural baseline: it pulls the assisted
    participant toward where the group is.

    Parameters
    ----------
    n : int
        Number of participants.
    assisted : int
        0-based index of the assisted participant (left out of the mean).

    Notes
    -----
    Bad data policy: non-finite phases are left out; with none left the output holds (run by run in a batch).
    """

    batchable = True

    def __init__(self, n: int, assisted: int, *, period: float | None = None) -> None:
        super().__init__(n, assisted, period)
        self.others = np.array([j for j in range(n) if j != assisted])

    def _output_rows(self) -> None:
        phases = self.theta.value[:, self.others]
        if math.isfinite(np.add.reduce(phases, axis=None)):  # one cheap check for the whole batch
            cos, sin = np.cos(phases), np.sin(phases)
        else:  # the non-finite phases are left out
            with np.errstate(invalid="ignore"):
                cos, sin = (np.where(np.isfinite(phases), f(phases), 0.0) for f in (np.cos, np.sin))
        c, s = cos.sum(axis=-1), sin.sum(axis=-1)
        theta_ref = np.mod(np.arctan2(s, c), 2.0 * math.pi)
        theta_ref[theta_ref >= 2.0 * math.pi] = 0.0
        np.copyto(self.theta_ref.value, theta_ref, where=(c != 0) | (s != 0))

    def output(self, k: int) -> None:
        if self.batch is not None:
            self._output_rows()
            return
        phases = self.theta.value[self.others]
        if not np.isfinite(phases).all():
            phases = phases[np.isfinite(phases)]
        c, s = np.cos(phases).sum(), np.sin(phases).sum()
        if c or s:
            self.theta_ref.value[...] = wrap_angle(math.atan2(s, c))


class OscillatorMotion(MotionComputer):
    """The deliverable's L3 reference: a virtual oscillator whose frequency a policy steers.

    ``θ_ref[k] = θ_L3[k]`` with ``θ_L3[k+1] = wrap(θ_L3[k] + dt (ω_L3[k] + gain Σ_j a_aj sin(θ_j[k] − θ_L3[k])))``,
    ``ω_L3[k] = clip(ω_L3[k−1] + ACTIONS[policy.act(...)], ±15)`` and ``θ_L3[0] = 0``. The oscillator sits at the
    assisted participant's node (coupled to its neighbours' own phases). Since the action of tick ``k`` first moves
    ``θ_L3[k+1]``, the output needs no input of the same tick.

    Parameters
    ----------
    policy : L3Policy
        Chooses the frequency increment every tick (e.g. a trained DQN or a look-ahead planner).
    n : int
        Number of participants.
    assisted : int
        0-based index of the assisted participant.
    gain : float
        Coupling gain of the virtual oscillator (the group's).
    omega_init : float
        ``ω_L3[−1]``; the deliverable's choice is the mean natural frequency.
    adjacency : graph spec
        The group's graph (``"ring"``, ``"all"``, ``("random", p, seed)`` or a weighted, possibly directed
        matrix); row ``assisted`` couples the oscillator.

    Notes
    -----
    Bad data policy: on a tick with a non-finite phase or λ the policy is not asked (it only ever sees finite
    contexts) and the oscillator coasts at its last frequency, without coupling.
    Runs a batch at once when the policy has ``act_rows(context)`` (context fields and actions one row
    per run, as :class:`~cogblocks.sync.DQNPolicy`): one call per tick for the batch; else per row.
    """

    _theta_feedthrough = False

    def __init__(
        self,
        policy: L3Policy,
        *,
        n: int,
        assisted: int,
        gain: float,
        omega_init: float,
        adjacency: Any = "ring",
        period: float | None = None,
    ) -> None:
        super().__init__(n, assisted, period)
        if not callable(getattr(policy, "act", None)):
            raise ValueError(f"OscillatorMotion: policy must have an act(context) method, got {policy!r}")
        self.policy = policy
        self.gain = finite_number(self, "gain", gain, low=0.0)
        self.omega_init = finite_number(self, "omega_init", omega_init, low=-OMEGA_L3_LIMIT, high=OMEGA_L3_LIMIT)
        self.graph = checked_graph(self, adjacency, n)
        self.coupling = Coupling(self.graph, n).row(assisted)
        self.others = np.array([j for j in range(n) if j != assisted])
        self.add_state("theta_l3", 0.0)
        self.add_state("omega_prev", self.omega_init)

    @property
    def batchable(self) -> bool:  # type: ignore[override]
        """Whether the policy chooses for a batch of runs in one call (``act_rows``)."""
        return callable(getattr(self.policy, "act_rows", None))

    def setup(self) -> None:
        for name, start in (("theta_l3", 0.0), ("omega_prev", self.omega_init)):  # one per run of a batch
            self.add_state(name, np.full(self.batch_shape, start) if self.batch is not None else start)

    def _update_rows(self, k: int) -> None:
        theta, lam, theta_l3, omega_prev = self.theta.value, self.lam.value, self.theta_l3, self.omega_prev
        ok = np.isfinite(theta).all(axis=-1) & np.isfinite(lam)
        theta, lam = np.where(ok[:, None], theta, 0.0), np.where(ok, lam, math.pi)  # the policy sees finite rows
        obs = l3_observation(theta_l3, theta[:, self.others], omega_prev)
        context = L3Context(k, obs, theta, theta_l3.copy(), lam, omega_prev.copy(), self.assisted)
        actions = np.asarray(self.policy.act_rows(context))
        omega = np.minimum(np.maximum(omega_prev + ACTIONS[actions], -OMEGA_L3_LIMIT), OMEGA_L3_LIMIT)
        pull = np.sin(theta - theta_l3[:, None]) @ self.coupling
        np.mod(np.where(ok, theta_l3 + self.dt * (omega + self.gain * pull), theta_l3 + self.dt * omega_prev),
               2.0 * math.pi, out=theta_l3)  # fmt: skip
        theta_l3[theta_l3 >= 2.0 * math.pi] = 0.0
        np.copyto(omega_prev, omega, where=ok)

    def plan_through(self, blender: BlenderParams) -> None:
        """Hand ``blender`` to the policy, if it predicts (a :class:`~cogblocks.sync.lookahead.LookaheadPolicy`)."""
        if callable(getattr(self.policy, "plan_through", None)):
            self.policy.plan_through(blender)

    def predictor(self) -> OscillatorMotion:
        """A copy that asks the policy's ``predictor()`` (a cheaper copy, as ``DQNPolicy``'s), else the policy."""
        cheaper = getattr(self.policy, "predictor", None)
        policy = cheaper() if callable(cheaper) else self.policy
        copied = OscillatorMotion(
            policy, n=self.n, assisted=self.assisted, gain=self.gain, omega_init=self.omega_init, adjacency=self.graph
        )
        copied.load_state_dict(self.state_dict())
        return copied

    def reset(self) -> None:
        super().reset()
        if hasattr(self.policy, "reset"):
            self.policy.reset(self.omega_init)

    def output(self, k: int) -> None:
        self.theta_ref.value[...] = self.theta_l3

    def update(self, k: int) -> None:
        if self.batch is not None:
            self._update_rows(k)
            return
        theta, lam = self.theta.value, float(self.lam.value)
        if not (np.all(np.isfinite(theta)) and math.isfinite(lam)):
            # no trustworthy context: keep the frequency, coast on the oscillator's own rate
            self.theta_l3 = wrap_angle(self.theta_l3 + self.dt * self.omega_prev)
            return
        self.theta_l3, self.omega_prev = self.step_oscillator(k, theta, lam, self.theta_l3, self.omega_prev, self.dt)

    def step_oscillator(
        self, k: int, theta: np.ndarray, lam: float, theta_l3: float, omega_prev: float, dt: float
    ) -> tuple[float, float]:
        """One tick (``dt`` s) of the virtual oscillator from ``(θ_L3, ω_prev)`` on finite ``theta`` and ``lam``:
        the policy's action, then the next ``(θ_L3, ω_L3)``; the block's state is untouched."""
        obs = l3_observation(theta_l3, theta[self.others], omega_prev)
        context = L3Context(k, obs, theta.copy(), theta_l3, lam, omega_prev, self.assisted)
        omega = min(max(omega_prev + ACTIONS[self.policy.act(context)], -OMEGA_L3_LIMIT), OMEGA_L3_LIMIT)
        pull = float(np.dot(self.coupling, np.sin(theta - theta_l3)))
        return wrap_angle(theta_l3 + dt * (omega + self.gain * pull)), omega
