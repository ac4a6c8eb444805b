"""A shield around any motion computer: its reference is followed only while a prediction says it does not lower r.

:class:`ShieldedMotion` runs a motion computer it wraps (any :class:`~cogblocks.sync.motion.MotionComputer`
block, e.g. the trained DQN's virtual oscillator) unchanged, every tick, and decides every period whether to emit
its reference or to do nothing (θ_ref = θ_L0, which leaves the assisted participant's phase unaltered: the group
runs as without L2). It decides as the pacing rule (:class:`~cogblocks.sync.pacing.PacingMotion`) does, on a
different pair of candidates; what the two share is
:class:`~cogblocks.sync.identified.PeriodicIdentifyingMotion` (the identification, the trust in the model, the
decision period) and the prediction's step and choice:

* the group is identified online from the observed phases
  (:meth:`PeriodicIdentifyingMotion._identify <cogblocks.sync.identified.PeriodicIdentifyingMotion._identify>`,
  recursive least squares on the phase increments, no oracle);
* from the state at a period's first tick, :meth:`ShieldedMotion.advance_rollout` predicts ``horizon`` seconds
  of the group on that model (:func:`~cogblocks.sync.identified.euler_step`, the blender's λ in the loop) twice,
  side by side: under the wrapped motion computer, a copy of which (its
  :meth:`~cogblocks.sync.motion.MotionComputer.predictor`) is run ahead tick by tick on the predicted phases
  as the block runs it on the observed ones, and under doing nothing; with ``backup`` seconds, both rows then
  go on doing nothing for that long (the backup policy: what the shield falls back to), so that a following
  whose cost shows only after it has stopped is scored with that cost;
* the wrapped reference is followed in the next period only if its predicted mean r beats doing nothing's by
  ``margin`` (:func:`~cogblocks.sync.identified.margin_choice`); otherwise the block does nothing.

Shielding (checking a learned controller's actions against a model and overriding the unsafe ones) is a standard
way to keep a policy's gains where the model vouches for them and nothing else: doing nothing is what cannot
lower r. The rollout is spread over the period (``ceil(horizon / dt / P)`` predicted ticks per tick, P the period in
ticks, without a backup part; with one, the policy part in the first half of the period and the backup part in the
rest), and its decision applies from the next period's first tick.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from cogblocks.sim.params import finite_number
from cogblocks.sync.identification import usable_phases
from cogblocks.sync.identified import NONE, PACE, PeriodicIdentifyingMotion, euler_step, margin_choice
from cogblocks.sync.model import BlenderParams
from cogblocks.sync.motion import MotionComputer
from cogblocks.sync.shield_rollout import PolicyRollout

__all__ = ["BACKUP", "DECIDE_EVERY", "FOLLOW", "HORIZON", "MARGIN", "PolicyRollout", "ShieldedMotion"]

#: Defaults: a decision every second on a prediction of 2 s following, then 8 s of doing nothing (the backup), and a
#: predicted gain of 0.001 in mean r over those 10 s needed to follow. A following whose cost shows only after it
#: stops is scored with that cost, and the small margin keeps the gains the model vouches for (the validation
#: groups' choice, docs/validation/sync.md, Claim 4).
DECIDE_EVERY = 1.0
HORIZON = 2.0
BACKUP = 8.0
MARGIN = 0.001

#: Mode of a :class:`ShieldedMotion` that emits its policy's reference (the other mode is ``NONE``).
FOLLOW = 3
#: The rollout's two rows: doing nothing, and the wrapped motion computer's reference of every predicted tick (a
#: ``PACE`` row at frequency 0 holds its anchor, set to that reference every tick).
_ROWS = np.array([NONE, PACE])
#: The backup part's rows: both doing nothing.
_IDLE = (np.array([NONE, NONE]), np.zeros(2), np.zeros(2))


class ShieldedMotion(PeriodicIdentifyingMotion):
    """A motion computer whose wrapped motion computer's reference is emitted only while a prediction says it does
    not lower r.

    See the module docstring. Before the identified model is trusted
    (:meth:`PeriodicIdentifyingMotion.model <cogblocks.sync.identified.PeriodicIdentifyingMotion.model>`:
    ``min_ticks`` increments and ``min_excitation``) and until the first decision, the block does nothing.

    Parameters
    ----------
    motion : MotionComputer
        The shielded motion computer, a block with the role's ports (not a diagram: the prediction runs a copy
        of it ahead). It runs every tick, followed or not, inside this block, which owns it: its declared state
        is part of this block's (``motion_*`` entries). Its :meth:`~cogblocks.sync.motion.MotionComputer.predictor`
        is the copy the prediction runs ahead; for an :class:`~cogblocks.sync.motion.OscillatorMotion` whose policy
        has a ``predictor()`` method (:meth:`DQNPolicy.predictor() <cogblocks.sync.dqn_policy.DQNPolicy.predictor>`)
        that copy asks the cheaper policy it returns. A policy's memory outside declared state is not predicted.
    adjacency : graph spec
        The group's graph (``"ring"``, ``"all"``, ``("random", p, seed)`` or a matrix), for the prediction.
    blender : BlenderParams
        The blender the predictions go through (the deliverable's by default).
    decide_every : float
        Seconds per period (a whole number of the block's steps): a decision every period, from a prediction
        started one period earlier.
    horizon : float
        Seconds predicted per decision under the wrapped motion computer (and under doing nothing).
    backup : float
        Seconds predicted after ``horizon``, both rows doing nothing (0: none). The prediction then asks whether
        following for ``horizon`` seconds and stopping leaves the group better off than doing nothing, over
        ``horizon + backup`` seconds. The backup part steps by the prediction step of
        :class:`~cogblocks.sync.identified.PeriodicIdentifyingMotion` (0.05 s, shortened where the identified
        coupling needs it), and the policy part is then predicted within the first half of the
        period, the backup part within the second.
    margin : float
        Predicted gain in mean r over doing nothing needed to follow.
    switch_margin : float
        Predicted gain needed to change from the current choice (doing nothing or following).
    min_ticks, min_excitation
        As in :class:`~cogblocks.sync.identified.PeriodicIdentifyingMotion`: increments observed, and information
        on the gain, before the model is trusted.

    Notes
    -----
    :attr:`predictions` (the scores ``(nothing, policy)`` of every decision) and :attr:`choices` (``NONE`` or
    :data:`FOLLOW` per decision) are records since the last reset, not block state. The prediction in progress
    (:attr:`job` and the :attr:`ahead` copy's state) is block state: the ``job_*`` and ``ahead_*`` entries,
    mirrored at the end of every update, so that a diagram restored from a snapshot continues it bit for bit.

    Bad data policy: on a tick with a phase that is not finite and within one turn of [0, 2π), or a non-finite
    λ, nothing is identified or decided (a decision due then is taken at the next good tick) and the wrapped
    motion computer is updated on NaN phases (an :class:`~cogblocks.sync.motion.OscillatorMotion` coasts at its
    last frequency); a prediction in progress advances (it works on its own predicted state). When following,
    θ_ref is the wrapped motion computer's; when doing nothing, θ_ref holds its last value on a tick with a bad
    phase. A finite λ outside the blender's [λ_min, λ_max] is clipped to it for the identification and the
    prediction.
    """

    def __init__(
        self,
        motion: MotionComputer,
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
        if not isinstance(motion, MotionComputer):
            raise ValueError(f"ShieldedMotion: motion must be a MotionComputer block, got {type(motion).__name__}")
        super().__init__(
            motion.n,
            motion.assisted,
            period,
            adjacency,
            blender,
            decide_every=decide_every,
            min_ticks=min_ticks,
            min_excitation=min_excitation,
        )
        self.horizon = finite_number(self, "horizon", horizon, low=0.0, low_open=True)
        self.margin = finite_number(self, "margin", margin, low=0.0)
        self.switch_margin = finite_number(self, "switch_margin", switch_margin, low=0.0)
        self.add_state("mode", NONE)
        self.choices: list[int] = []
        self.backup = finite_number(self, "backup", backup, low=0.0)
        # the wrapped block and its predicting copy are work objects: their state lives in the
        # declared motion_* / ahead_* mirrors, so a restored snapshot rebuilds them
        self.add_scratch("motion", motion)
        self.add_scratch("ahead", motion.predictor())
        self._motion_fields = tuple(motion.state_dict()["state"])
        self._declare_mirrors()
        # the prediction in progress by fields, meaningful while job_active (an idle one declares shapes and types)
        self.add_state("job_active", False)
        idle = PolicyRollout.start(np.zeros(self.n), 0.0, (np.zeros(self.n), 0.0), k=0, dt=0.0, steps=0)
        for name, value in idle.state().items():
            self.add_state(f"job_{name}", value)
        self._job_fields = tuple(idle.state())
        self.add_scratch("job", None)  # rebuilt from the job_* fields on every restore
        self.predictions: list[tuple[float, float]] = []

    def _declare_mirrors(self) -> None:
        """Declare (again, once the copies are set up) the wrapped block's and its copy's state as this block's."""
        for name, value in self.motion.state_dict()["state"].items():
            self.add_state(f"motion_{name}", value)
            self.add_state(f"ahead_{name}", value)

    def setup(self) -> None:
        super().setup()
        for block in (self.motion, self.ahead):
            block.dt, block.every = self.dt * self.every, 1
            block.setup()
        self._declare_mirrors()
        self._keep_motion()

    def plan_through(self, blender: BlenderParams) -> None:
        super().plan_through(blender)
        self.motion.plan_through(blender)
        self.ahead.plan_through(blender)

    def reset(self) -> None:
        super().reset()
        self.motion.reset()
        self.ahead.reset()
        self._keep_motion()
        self.job, self.predictions, self.choices = None, [], []

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        super().load_state_dict(state)
        for name in self._motion_fields:
            setattr(self.motion, name, getattr(self, f"motion_{name}"))
            setattr(self.ahead, name, getattr(self, f"ahead_{name}"))
        fields = {name: getattr(self, f"job_{name}") for name in self._job_fields}
        self.job = PolicyRollout.from_state(fields) if self.job_active else None

    def output(self, k: int) -> None:
        theta = np.asarray(self.theta.value, dtype=float)
        self.motion.theta.value[...] = theta
        self.motion.output(k)
        if self.mode == FOLLOW:
            self.theta_ref.value[...] = self.motion.theta_ref.value
        elif usable_phases(theta):
            self.theta_ref.value[...] = theta[self.assisted]

    def update(self, k: int) -> None:
        theta, lam = np.asarray(self.theta.value, dtype=float), float(self.lam.value)
        dt = self.dt * self.every
        if k % self.decide_ticks == 0:
            self.due = True
        usable = usable_phases(theta) and math.isfinite(lam)
        if not usable:
            self.previous[...] = math.nan
        else:
            clipped = min(max(lam, self.blender.lam_min), self.blender.lam_max)
            ref = float(self.motion.theta_ref.value) if self.mode == FOLLOW else float(theta[self.assisted])
            self._identify(theta, clipped, ref, dt)
            if self.due:
                if self.job is not None and self.job.done:
                    self._finish(self.job.scores)
                self.job = None
                model = self.model()
                if model is not None:
                    self.job = self._rollout(theta, clipped, model, k, dt)
                self.due = False
        self.motion.theta.value[...] = theta if usable else math.nan
        self.motion.lam.value[...] = lam
        self.motion.update(k)
        self._keep_motion()
        if self.job is not None and not self.job.done:
            self._advance_job()
        self._keep_job()

    def _keep_motion(self) -> None:
        """Mirror the wrapped block's state into this block's (references: they follow its arrays)."""
        for name in self._motion_fields:
            setattr(self, f"motion_{name}", getattr(self.motion, name))

    def _keep_job(self) -> None:
        """Mirror the prediction in progress into the block's state (references, no copy: they follow its arrays)."""
        self.job_active = self.job is not None
        if self.job is not None:
            for name, value in self.job.state().items():
                setattr(self, f"job_{name}", value)
            for name in self._motion_fields:
                setattr(self, f"ahead_{name}", getattr(self.ahead, name))

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
        return self.start_rollout(
            theta, lam, model, k=k, dt=dt, steps=steps, backup_steps=backup_steps, backup_step=backup_step
        )

    def start_rollout(
        self,
        theta: np.ndarray,
        lam: float,
        model: tuple[np.ndarray, float],
        *,
        k: int,
        dt: float,
        steps: int,
        backup_steps: int = 0,
        backup_step: float = 0.0,
    ) -> PolicyRollout:
        """A prediction from phases ``theta``, threshold ``lam`` and the wrapped motion computer's state now.

        The :attr:`ahead` copy takes the wrapped block's state and steps by ``dt``; the arguments are
        :meth:`PolicyRollout.start`'s.
        """
        self.ahead.load_state_dict(self.motion.state_dict())
        self.ahead.dt = dt
        return PolicyRollout.start(
            theta, lam, model, k=k, dt=dt, steps=steps, backup_steps=backup_steps, backup_step=backup_step
        )

    def advance_rollout(self, job: PolicyRollout, budget: int, backup_budget: int = 0) -> None:
        """Predict at most ``budget`` more ticks of ``job``'s policy part, then ``backup_budget`` backup steps.

        Row 1's reference of a tick is the :attr:`ahead` copy's output on row 1's phases; the copy is then
        updated on them and row 1's λ, as the block updates the wrapped motion computer on the observed ones. In
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
        ahead = self.ahead
        for _ in range(budget):
            if job.following_done:
                return
            k = job.k + job.done_steps
            ahead.theta.value[...] = np.mod(job.theta[1], 2.0 * math.pi)
            ahead.output(k)
            rows = (_ROWS, np.zeros(2), np.array([0.0, float(ahead.theta_ref.value)]))
            ahead.lam.value[...] = job.lam[1]
            ahead.update(k)
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
