"""L3 motion computers for the PoP of Social Connectedness: policies choosing the virtual oscillator's frequency.

Every policy implements :class:`L3Policy`: ``reset(omega_init)`` at the start of an episode, then
``act(context)`` once per tick returning an index into :data:`ACTIONS`, the frequency increment of
the virtual oscillator whose phase is the blender's reference. :class:`DQNPolicy` uses only
``context.obs``; :class:`LookaheadPolicy` uses the full state in the context and a model of the group.
"""

from __future__ import annotations

from importlib import resources
from os import PathLike

import numpy as np
import torch
from torch import nn

from cogblocks.blocks.motion import L3Policy
from cogblocks.data.groups import SyncGroup
from cogblocks.training.sync_env import (
    ACTIONS,
    HOLD_ACTION,
    OMEGA_L3_LIMIT,
    BlenderParams,
    L3Context,
    SyncModel,
    l3_observation,
    order_parameter,
)

__all__ = [
    "ACTIONS",
    "DQNPolicy",
    "L3Context",
    "L3Policy",
    "L3QNetwork",
    "LookaheadPolicy",
    "l3_observation",
]

OBS_SIZE = 3


class L3QNetwork(nn.Module):
    """Q-network of the L3 policy: observation (3) -> 128 -> 64 -> one value per action (11), ReLU.

    The observation is used as is, without normalisation, as in the original motion computer.
    """

    def __init__(self) -> None:
        super().__init__()
        self.layers = nn.Sequential(
            nn.Linear(OBS_SIZE, 128),
            nn.ReLU(),
            nn.Linear(128, 64),
            nn.ReLU(),
            nn.Linear(64, len(ACTIONS)),
        )

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        """Action values, shape (..., 11), of observations of shape (..., 3)."""
        return self.layers(obs)


class DQNPolicy:
    """Greedy policy of a trained :class:`L3QNetwork`.

    Parameters
    ----------
    network : L3QNetwork
        Trained network; switched to evaluation mode.
    """

    def __init__(self, network: L3QNetwork) -> None:
        self.network = network.eval()

    @classmethod
    def from_file(cls, path: str | PathLike[str]) -> DQNPolicy:
        """Load a ``state_dict`` saved by :mod:`cogblocks.training.sync_dqn`."""
        network = L3QNetwork()
        network.load_state_dict(torch.load(path, map_location="cpu", weights_only=True))
        return cls(network)

    @classmethod
    def default(cls) -> DQNPolicy:
        """Policy with the weights shipped in ``cogblocks/data/weights/sync_dqn.pt``."""
        with resources.as_file(resources.files("cogblocks.data") / "weights" / "sync_dqn.pt") as path:
            return cls.from_file(path)

    def reset(self, omega_init: float) -> None:
        """The policy is memoryless: nothing to reset."""

    def act(self, context: L3Context) -> int:
        """Action with the highest value for ``context.obs``."""
        with torch.no_grad():
            values = self.network(torch.as_tensor(context.obs, dtype=torch.float32))
        return int(values.argmax())


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
    replan_every : int
        Ticks between two plans; 1 plans every tick.
    """

    def __init__(self, model: SyncModel, horizon: int = 25, replan_every: int = 1) -> None:
        if np.ndim(model.omega) != 1:
            raise ValueError("the look-ahead model describes a single episode: omega must have shape (N,)")
        if horizon < 1 or replan_every < 1:
            raise ValueError("horizon and replan_every must be at least 1")
        self.model = model
        self.horizon = horizon
        self.replan_every = replan_every
        self._action = HOLD_ACTION

    @classmethod
    def for_group(cls, group: SyncGroup, *, blender: BlenderParams | None = None, horizon: int = 25,
                  replan_every: int = 1) -> LookaheadPolicy:
        """Look-ahead with an exact model of a bundled group and the given blender."""
        return cls(SyncModel.from_group(group, blender=blender), horizon, replan_every)

    def reset(self, omega_init: float) -> None:
        """Forget the last plan."""
        self._action = HOLD_ACTION

    def act(self, context: L3Context) -> int:
        """Best action of a fresh plan on planning ticks, else the current plan's action."""
        if context.k % self.replan_every == 0:
            self._action = int(np.argmax(self.predicted_order_parameter(context)))
        return self._action

    def predicted_order_parameter(self, context: L3Context) -> np.ndarray:
        """Mean order parameter over the horizon predicted for each action, shape (11,)."""
        n_actions = len(ACTIONS)
        # Tick k's blending is the same for every action: do it once, then fan out.
        theta_tilde, _, lam = self.model.blend(context.theta, np.asarray(context.theta_l3), np.asarray(context.lam))
        theta = np.broadcast_to(context.theta, (n_actions, self.model.n))
        theta_tilde = np.broadcast_to(theta_tilde, theta.shape)
        theta_l3 = np.full(n_actions, context.theta_l3)
        lam = np.full(n_actions, float(lam))
        omega_l3 = np.full(n_actions, context.omega_prev)
        total = np.zeros(n_actions)
        for _ in range(self.horizon):
            omega_l3 = np.clip(omega_l3 + ACTIONS, -OMEGA_L3_LIMIT, OMEGA_L3_LIMIT)
            theta, theta_l3 = self.model.advance(theta, theta_tilde, theta_l3, omega_l3)
            theta_tilde, _, lam = self.model.blend(theta, theta_l3, lam)
            total += order_parameter(theta_tilde)
        return total / self.horizon
