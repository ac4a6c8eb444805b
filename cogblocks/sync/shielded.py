"""A shield for a learned L3 policy: its reference is followed only while a prediction says it does not lower r.

:class:`ShieldedMotion` runs an L3 motion computer (:class:`~cogblocks.sync.motion.OscillatorMotion`, e.g. the
trained DQN's virtual oscillator) unchanged, every tick, and decides every period whether to emit its reference
or to do nothing (θ_ref = θ_L0, which leaves the assisted participant's phase unaltered: the group runs as
without L2). The decision is :class:`~cogblocks.sync.pacing.PacingMotion`'s, on a different pair of candidates:

* the group is identified online from the observed phases (:meth:`PacingMotion._identify`, recursive least
  squares on the phase increments, no oracle);
* from the state at a period's first tick, :meth:`ShieldedMotion.advance_rollout` predicts ``horizon`` seconds
  of the group on that model (:func:`~cogblocks.sync.pacing.euler_step`, the blender's λ in the loop) twice,
  side by side: under the policy, whose oscillator and network are run ahead tick by tick on the predicted
  phases as the block runs them on the observed ones, and under doing nothing; with ``backup`` seconds, both
  rows then go on doing nothing for that long (the backup policy: what the shield falls back to), so that a
  following whose cost shows only after it has stopped is scored with that cost;
* the policy is followed in the next period only if its predicted mean r beats doing nothing's by ``margin``
  (:func:`~cogblocks.sync.pacing.margin_choice`); otherwise the block does nothing.

Shielding (checking a learned controller's actions against a model and overriding the unsafe ones) is a standard
way to keep a policy's gains where the model vouches for them and nothing else: doing nothing is what cannot
lower r. The rollout is spread over the period (``ceil(horizon / dt / P)`` predicted ticks per tick, P the period in
ticks, without a backup part; with one, the policy part in the first half of the period and the backup part in the
rest), and its decision applies from the next period's first tick.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cogblocks.blocks.angles import wrap_angle
from cogblocks.sim.params import finite_number
from cogblocks.sync.identification import usable_phases
from cogblocks.sync.model import BlenderParams
from cogblocks.sync.motion import L3Policy, OscillatorMotion
from cogblocks.sync.pacing import NONE, PACE, PacingMotion, euler_step, margin_choice

__all__ = ["BACKUP", "DECIDE_EVERY", "FOLLOW", "HORIZON", "MARGIN", "PolicyRollout", "ShieldedMotion"]

#: Defaults: a decision every second on a prediction of 2 s following the policy, then 8 s of doing nothing (the
#: backup), and a predicted gain of 0.001 in mean r over those 10 s needed to follow it. Chosen on validation groups
#: 0–119 among four settings (fewest lowered, then the highest mean change) and confirmed on groups 120–299 against
#: the first version's 1 s, no backup, 0.005 (docs/pop-sync.md, "The shield's backup part").
DECIDE_EVERY = 1.0
HORIZON = 2.0
BACKUP = 8.0
MARGIN = 0.001

#: Mode of a :class:`ShieldedMotion` that emits its policy's reference (the other mode is ``NONE``).
FOLLOW = 3
#: The rollout's two rows: doing nothing, and a reference re-anchored every tick on the policy's oscillator.
_ROWS = np.array([NONE, PACE])
#: The backup part's rows: both doing nothing.
_IDLE = (np.array([NONE, NONE]), np.zeros(2), np.zeros(2))


@dataclass
class PolicyRollout:
    """The state of one prediction: doing nothing (row 0) and following the policy (row 1), side by side.

    Plain data, :meth:`ShieldedMotion.advance_rollout` runs it. A block keeps it as declared state through
    :meth:`state` (numbers and arrays, which a snapshot file holds) and :meth:`from_state`.

    Attributes
    ----------
    theta : ndarray, shape (2, N)
        The participants' predicted own phases of both rows.
    lam : ndarray, shape (2,)
        The blender's predicted λ of both rows.
    oscillator : ndarray, shape (2,)
        The policy's predicted ``(θ_L3, ω_prev)`` in row 1.
    model : (ndarray, float)
        Natural frequencies ω (rad/s) and coupling gain K the prediction runs on.
    k : int
        The tick the prediction starts at.
    dt : float
        The tick (s): the policy acts every tick, so the prediction steps by ``dt``.
    steps : int
        Ticks predicted under the policy (row 1) or doing nothing (row 0).
    backup_steps : int
        Steps of ``backup_step`` seconds predicted after them, both rows doing nothing.
    backup_step : float
        The Euler step (s) of the backup part.
    done_steps, done_backup : int
        Ticks and backup steps predicted so far.
    total : ndarray, shape (2,)
        Time integral of the predicted r of both rows so far (r·dt summed); :attr:`scores` divide it by the
        predicted time.
    """

    theta: np.ndarray
    lam: np.ndarray
    oscillator: np.ndarray
    model: tuple[np.ndarray, float]
    k: int
    dt: float
    steps: int
    backup_steps: int = 0
    backup_step: float = 0.0
    done_steps: int = 0
    done_backup: int = 0
    total: np.ndarray = field(default_factory=lambda: np.zeros(2))

    @classmethod
    def start(
        cls,
        theta: np.ndarray,
        lam: float,
        oscillator: tuple[float, float],
        model: tuple[np.ndarray, float],
        *,
        k: int,
        dt: float,
        steps: int,
        backup_steps: int = 0,
        backup_step: float = 0.0,
    ) -> PolicyRollout:
        """Both rows at the phases ``theta`` and threshold ``lam`` of tick ``k``, the policy at ``(θ_L3, ω_prev)``."""
        theta = np.tile(np.asarray(theta, dtype=float), (2, 1))
        lam = np.full(2, float(lam))
        return cls(theta, lam, np.array(oscillator, dtype=float), model, k, dt, steps, backup_steps, backup_step)

    def state(self) -> dict[str, Any]:
        """The rollout as numbers and arrays (no copy): its fields, the model split into ``omega`` and ``gain``."""
        fields = {name: value for name, value in vars(self).items() if name != "model"}
        return fields | {"omega": self.model[0], "gain": self.model[1]}

    @classmethod
    def from_state(cls, state: Mapping[str, Any]) -> PolicyRollout:
        """The rollout :meth:`state` returned (its arrays copied)."""
        fields = {name: np.array(value) if isinstance(value, np.ndarray) else value for name, value in state.items()}
        model = (fields.pop("omega"), fields.pop("gain"))
        return cls(model=model, **fields)

    @property
    def following_done(self) -> bool:
        """The part under the policy is predicted (the backup part, if any, may remain)."""
        return self.done_steps >= self.steps

    @property
    def done(self) -> bool:
        return self.following_done and self.done_backup >= self.backup_steps

    @property
    def scores(self) -> np.ndarray:
        """Predicted mean r over the predicted time of (doing nothing, following the policy), once :attr:`done`."""
        if not self.done:
            raise RuntimeError("PolicyRollout: the scores are known only once every step is done")
        return self.total / (self.steps * self.dt + self.backup_steps * self.backup_step)


class ShieldedMotion(PacingMotion):
    """An L3 motion computer whose reference is emitted only while a prediction says it does not lower r.

    See the module docstring. Before the identified model is trusted (as :class:`PacingMotion`: ``min_ticks``
    increments and ``min_excitation``) and until the first decision, the block does nothing.

    Parameters
    ----------
    motion : OscillatorMotion
        The shielded policy's motion computer. Its policy must choose from the context alone (the prediction asks
        it about predicted contexts between the block's own ticks); a policy with a ``predictor()`` method (e.g.
        :meth:`DQNPolicy.predictor() <cogblocks.sync.dqn_policy.DQNPolicy.predictor>`) is asked through the
        cheaper copy it returns. Its oscillator runs every tick, followed or not.
    adjacency : graph spec
        The group's graph (``"ring"``, ``"all"``, ``("random", p, seed)`` or a matrix), for the prediction.
    blender : BlenderParams
        The blender the predictions go through (the deliverable's by default).
    decide_every : float
        Seconds per period (a whole number of the block's steps): a decision every period, from a prediction
        started one period earlier.
    horizon : float
        Seconds predicted per decision under the policy (and under doing nothing).
    backup : float
        Seconds predicted after ``horizon``, both rows doing nothing (0: none). The prediction then asks whether
        following the policy for ``horizon`` seconds and stopping leaves the group better off than doing nothing,
        over ``horizon + backup`` seconds. The backup part steps by :class:`PacingMotion`'s ``step`` (shortened
        where the identified coupling needs it), and the policy part is then predicted within the first half
        of the period, the backup part within the second.
    margin : float
        Predicted gain in mean r over doing nothing needed to follow the policy.
    switch_margin : float
        Predicted gain needed to change from the current choice (doing nothing or following).
    min_ticks, min_excitation
        As in :class:`PacingMotion`.

    Notes
    -----
    :attr:`predictions` (the scores ``(nothing, policy)`` of every decision) and :attr:`choices` (``NONE`` or
    :data:`FOLLOW` per decision) are records since the last reset, not block state. The prediction in progress
    (:attr:`job`) is block state: the ``job_*`` entries (:meth:`PolicyRollout.state`, mirrored at the end of every
    update), so that a diagram restored from a snapshot continues it bit for bit.

    Bad data policy: on a tick with a phase that is not finite and within one turn of [0, 2π), or a non-finite
    λ, nothing is identified or decided (a decision due then is taken at the next good tick) and the policy is
    not asked: its oscillator coasts at its last frequency, as in :class:`OscillatorMotion`; a prediction in
    progress advances (it works on its own predicted state). When following, θ_ref is the oscillator's phase;
    when doing nothing, θ_ref holds its last value on a tick with a bad phase. A finite λ outside the blender's
    [λ_min, λ_max] is clipped to it for the identification and the prediction.
    """

    def __init__(
        self,
        motion: OscillatorMotion,
        *,
        adjacency: Any = "ring",
        blender: BlenderParams | None = None,
        decide_every: float = DECIDE_EVERY,
        horizon: float = HORIZON,
        backup: float = BACKUP,
        margin: float = MARGIN,
        switch_margin: float = 0.0,
        min_ticks: int = 100,
        min_excitation: float = 1.0,
        period: float | None = None,
    ) -> None:
        if not isinstance(motion, OscillatorMotion):
            raise ValueError(f"ShieldedMotion: motion must be an OscillatorMotion, got {type(motion).__name__}")
        super().__init__(
            motion.n,
            motion.assisted,
            adjacency=adjacency,
            blender=blender,
            decide_every=decide_every,
            horizon=horizon,
            margin=margin,
            switch_margin=switch_margin,
            start="none",
            min_ticks=min_ticks,
            min_excitation=min_excitation,
            period=period,
        )
        self.backup = finite_number(self, "backup", backup, low=0.0)
        self.motion = motion
        cheaper = getattr(motion.policy, "predictor", None)
        self.predictor: L3Policy = cheaper() if callable(cheaper) else motion.policy
        self.add_state("theta_l3", 0.0)
        self.add_state("omega_prev", motion.omega_init)
        # the prediction in progress by fields, meaningful while job_active (an idle one declares shapes and types)
        self.add_state("job_active", False)
        idle = PolicyRollout.start(np.zeros(self.n), 0.0, (0.0, 0.0), (np.zeros(self.n), 0.0), k=0, dt=0.0, steps=0)
        for name, value in idle.state().items():
            self.add_state(f"job_{name}", value)
        self._job_fields = tuple(idle.state())
        self.job: PolicyRollout | None = None
        self.predictions: list[tuple[float, float]] = []

    def reset(self) -> None:
        super().reset()
        self.motion.reset()  # the policy's episode memory
        if self.predictor is not self.motion.policy and hasattr(self.predictor, "reset"):
            self.predictor.reset(self.motion.omega_init)
        self.job, self.predictions = None, []

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        super().load_state_dict(state)
        fields = {name: getattr(self, f"job_{name}") for name in self._job_fields}
        self.job = PolicyRollout.from_state(fields) if self.job_active else None

    def output(self, k: int) -> None:
        if self.mode == FOLLOW:
            self.theta_ref.value[...] = self.theta_l3
            return
        theta = np.asarray(self.theta.value, dtype=float)
        if usable_phases(theta):
            self.theta_ref.value[...] = theta[self.assisted]

    def update(self, k: int) -> None:
        theta, lam = np.asarray(self.theta.value, dtype=float), float(self.lam.value)
        dt = self.dt * self.every
        if k % self.decide_ticks == 0:
            self.due = True
        if not (usable_phases(theta) and math.isfinite(lam)):
            self.previous[...] = math.nan
            self.theta_l3 = wrap_angle(self.theta_l3 + dt * self.omega_prev)
        else:
            clipped = min(max(lam, self.blender.lam_min), self.blender.lam_max)
            ref = self.theta_l3 if self.mode == FOLLOW else float(theta[self.assisted])
            self._identify(theta, clipped, ref, dt)
            if self.due:
                if self.job is not None and self.job.done:
                    self._finish(self.job.scores)
                self.job = None
                model = self.model()
                if model is not None:
                    self.job = self._rollout(theta, clipped, model, k, dt)
                self.due = False
            self.theta_l3, self.omega_prev = self.motion.step_oscillator(
                k, theta, lam, self.theta_l3, self.omega_prev, dt
            )
        if self.job is not None and not self.job.done:
            self._advance_job()
        self._keep_job()

    def _keep_job(self) -> None:
        """Mirror the prediction in progress into the block's state (references, no copy: they follow its arrays)."""
        self.job_active = self.job is not None
        if self.job is not None:
            for name, value in self.job.state().items():
                setattr(self, f"job_{name}", value)

    def _advance_job(self) -> None:
        """One tick's share of the prediction in progress: ``decide_ticks`` calls from its start finish it."""
        job = self.job
        if not job.backup_steps:
            self.advance_rollout(job, math.ceil(job.steps / self.decide_ticks))
            return
        # the policy part in the first half of the period, the backup part in the rest, from the tick the first ends
        first = max(1, self.decide_ticks // 2)
        rest = max(1, self.decide_ticks - first)
        self.advance_rollout(job, math.ceil(job.steps / first), math.ceil(job.backup_steps / rest))

    def _rollout(
        self, theta: np.ndarray, lam: float, model: tuple[np.ndarray, float], k: int, dt: float
    ) -> PolicyRollout:
        """The prediction of the decision that applies one period from now, from this tick's state."""
        steps = max(1, round(self.horizon / dt))
        backup_step = self._stable_step(model[1])
        backup_steps = round(self.backup / backup_step) if self.backup > 0.0 else 0
        oscillator = (self.theta_l3, self.omega_prev)
        return PolicyRollout.start(
            theta, lam, oscillator, model, k=k, dt=dt, steps=steps, backup_steps=backup_steps, backup_step=backup_step
        )

    def advance_rollout(self, job: PolicyRollout, budget: int, backup_budget: int = 0) -> None:
        """Predict at most ``budget`` more ticks of ``job``'s policy part, then ``backup_budget`` backup steps.

        Row 1's reference of a tick is the oscillator's phase then; the policy (:attr:`predictor`) acts on the
        phases and λ of row 1, and the oscillator moves as :meth:`OscillatorMotion.step_oscillator` moves it. In
        the backup part both rows do nothing.
        """
        self._advance_following(job, budget)
        if job.following_done:
            for _ in range(min(backup_budget, job.backup_steps - job.done_backup)):
                job.theta, job.lam, r = euler_step(
                    job.theta, job.lam, job.model, self.adjacency, self.assisted, self.blender, _IDLE, 0.0,
                    job.backup_step,
                )  # fmt: skip
                job.total += r * job.backup_step
                job.done_backup += 1

    def _advance_following(self, job: PolicyRollout, budget: int) -> None:
        for _ in range(budget):
            if job.following_done:
                return
            theta_l3, omega_prev = job.oscillator
            rows = (_ROWS, np.zeros(2), np.array([0.0, theta_l3]))
            following = np.mod(job.theta[1], 2.0 * math.pi)
            job.oscillator[:] = self.motion.step_oscillator(
                job.k + job.done_steps, following, float(job.lam[1]), theta_l3, omega_prev, job.dt, self.predictor
            )
            job.theta, job.lam, r = euler_step(
                job.theta, job.lam, job.model, self.adjacency, self.assisted, self.blender, rows, 0.0, job.dt
            )
            job.total += r * job.dt
            job.done_steps += 1

    def _finish(self, scores: np.ndarray) -> None:
        """Choose between doing nothing and following for the next period, from a finished prediction."""
        best = margin_choice(_ROWS, scores, 0 if self.mode == NONE else 1, self.margin, self.switch_margin)
        self.mode = FOLLOW if best == 1 else NONE
        self.predictions.append((float(scores[0]), float(scores[1])))
        self.choices.append(self.mode)
