"""The look-ahead L3 policy: the frequency increment that maximises the coming order parameter on the group model."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np

from cogblocks.data.groups import SyncGroup
from cogblocks.sync.model import BlenderParams, SyncModel, order_parameter
from cogblocks.sync.motion import ACTIONS, HOLD_ACTION, OMEGA_L3_LIMIT, L3Context
from cogblocks.sync.periods import seconds_ticks

__all__ = ["LookaheadPolicy"]


class LookaheadPolicy:
    """Model-based policy: simulate every action over a short horizon and keep the best one.

    At a planning tick, the group, the blender and the virtual oscillator are simulated ``horizon``
    ticks ahead once per action, all 11 at once, each repeating its action at every simulated tick
    (so the frequency keeps moving by the same increment); the action with the highest mean order
    parameter over ticks ``k + 1 ... k + horizon`` is chosen (``r[k]`` does not depend on it). Between
    planning ticks the chosen action is repeated, which is what the plan assumed.

    Parameters
    ----------
    model : SyncModel
        Model of the group for one episode (``omega`` of shape (N,)), with the blender in the loop.
    horizon : int
        Simulated ticks per plan.
    decide_every : float, optional
        Seconds between two plans, a positive multiple of the model's step; ``None`` plans every tick.
    replan_every : int, optional
        Deprecated: the same in ticks.
    """

    def __init__(
        self,
        model: SyncModel,
        horizon: int = 25,
        decide_every: float | None = None,
        *,
        replan_every: int | None = None,
    ) -> None:
        if np.ndim(model.omega) != 1:
            raise ValueError("the look-ahead model describes a single episode: omega must have shape (N,)")
        if horizon < 1:
            raise ValueError("horizon must be at least 1")
        # the former unit, ticks: replan_every, or an int in decide_every's place, for one release
        if isinstance(decide_every, (int, np.integer)) and not isinstance(decide_every, bool):
            replan_every, decide_every = int(decide_every), None
        if replan_every is not None:
            if replan_every < 1:
                raise ValueError("replan_every must be at least 1")
            warnings.warn(
                f"LookaheadPolicy: replan_every (ticks) is deprecated; give decide_every in seconds "
                f"(decide_every={replan_every * model.dt:g})",
                DeprecationWarning,
                stacklevel=2,
            )
            ticks = int(replan_every)
        else:
            ticks = 1 if decide_every is None else seconds_ticks(self, "decide_every", decide_every, model.dt)
        self.model = model
        self.horizon = horizon
        #: Ticks of the model's step between two plans.
        self.decide_ticks = ticks
        self._action = HOLD_ACTION

    @property
    def replan_every(self) -> int:
        """Deprecated: :attr:`decide_ticks`."""
        warnings.warn("LookaheadPolicy.replan_every is deprecated: use decide_ticks", DeprecationWarning, stacklevel=2)
        return self.decide_ticks

    @classmethod
    def for_group(
        cls,
        group: SyncGroup,
        *,
        blender: BlenderParams | None = None,
        horizon: int = 25,
        decide_every: float | None = None,
    ) -> LookaheadPolicy:
        """Look-ahead with an exact model of a group (on its graph) and the given blender."""
        return cls(SyncModel.from_group(group, blender=blender), horizon, decide_every)

    def plan_through(self, blender: BlenderParams) -> None:
        """Predict through ``blender``, the blender of the diagram the policy's motion computer sits in."""
        self.model = dataclasses.replace(self.model, blender=blender)

    def reset(self, omega_init: float) -> None:
        """Forget the last plan."""
        self._action = HOLD_ACTION

    def act(self, context: L3Context) -> int:
        """Best action of a fresh plan on planning ticks, else the current plan's action."""
        if context.k % self.decide_ticks == 0:
            self._action = int(np.argmax(self.predicted_order_parameter(context)))
        return self._action

    def predicted_order_parameter(self, context: L3Context) -> np.ndarray:
        """Mean order parameter over the horizon predicted for each action, shape (11,)."""
        n_actions = len(ACTIONS)
        # Tick k's blending is the same for every action: do it once, then fan out.
        # tick k's alteration is not known here (no slew limit on it); the predicted ones follow from it
        theta_tilde, shift, lam = self.model.blend(context.theta, np.asarray(context.theta_l3), np.asarray(context.lam))
        theta = np.broadcast_to(context.theta, (n_actions, self.model.n))
        theta_tilde = np.broadcast_to(theta_tilde, theta.shape)
        theta_l3 = np.full(n_actions, context.theta_l3)
        lam = np.full(n_actions, float(lam))
        shift = np.full(n_actions, float(shift))
        omega_l3 = np.full(n_actions, context.omega_prev)
        total = np.zeros(n_actions)
        for _ in range(self.horizon):
            omega_l3 = np.clip(omega_l3 + ACTIONS, -OMEGA_L3_LIMIT, OMEGA_L3_LIMIT)
            theta, theta_l3 = self.model.advance(theta, theta_tilde, theta_l3, omega_l3)
            theta_tilde, shift, lam = self.model.blend(theta, theta_l3, lam, shift)
            total += order_parameter(theta_tilde)
        return total / self.horizon
