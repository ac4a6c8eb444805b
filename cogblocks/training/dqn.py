"""DQN learning machinery shared by the trainers: replay buffer, TD update step, target-network copy.

The trainers keep what differs between them: the environment loop, the exploration schedule and its
random draws, when the target network is refreshed, the discount of a transition and model selection.
Everything here draws its randomness from the generator it is given, so a trainer's seed still fixes
the order of every draw.
"""

from __future__ import annotations

import copy
from typing import Generic, NamedTuple, TypeVar

import numpy as np
import torch
from torch import nn

__all__ = ["Batch", "DQNLearner", "ReplayBuffer"]

Q = TypeVar("Q", bound=nn.Module)


class Batch(NamedTuple):
    """Transitions sampled from a :class:`ReplayBuffer`, one row each."""

    obs: torch.Tensor
    actions: torch.Tensor
    rewards: torch.Tensor
    next_obs: torch.Tensor
    terminal: torch.Tensor


class ReplayBuffer:
    """Circular buffer of transitions ``(obs, action, reward, next_obs, terminal)``, sampled uniformly.

    Parameters
    ----------
    capacity : int
        Transitions kept; the oldest are overwritten first.
    obs_size : int
        Length of an observation.
    """

    def __init__(self, capacity: int, obs_size: int) -> None:
        self.capacity = capacity
        # float32 storage: the networks' dtype, so sampled batches need no conversion.
        self.obs = np.zeros((capacity, obs_size), dtype=np.float32)
        self.next_obs = np.zeros((capacity, obs_size), dtype=np.float32)
        self.actions = np.zeros(capacity, dtype=np.int64)
        self.rewards = np.zeros(capacity, dtype=np.float32)
        self.terminal = np.zeros(capacity, dtype=np.float32)
        self.size = 0
        self._cursor = 0

    def add(
        self, obs: np.ndarray, actions: np.ndarray, rewards: np.ndarray, next_obs: np.ndarray, terminal: np.ndarray
    ) -> None:
        """Store a batch of transitions, overwriting the oldest when full.

        Parameters
        ----------
        obs, next_obs : numpy.ndarray, shape (B, obs_size)
            Observations before and after each action.
        actions : numpy.ndarray of int, shape (B,)
            Action indices.
        rewards : numpy.ndarray, shape (B,)
            Rewards of the transitions.
        terminal : numpy.ndarray of bool, shape (B,)
            True where the episode terminated, so that ``next_obs`` has no value to bootstrap from
            (an episode cut by a time limit is not terminated).
        """
        rows = (self._cursor + np.arange(len(actions))) % self.capacity
        self.obs[rows], self.actions[rows], self.rewards[rows] = obs, actions, rewards
        self.next_obs[rows], self.terminal[rows] = next_obs, terminal
        self._cursor = int(rows[-1] + 1) % self.capacity
        self.size = min(self.size + len(actions), self.capacity)

    def sample(self, rng: np.random.Generator, batch_size: int) -> Batch:
        """Uniform sample, with replacement, of ``batch_size`` stored transitions (one draw of ``rng``)."""
        rows = rng.integers(self.size, size=batch_size)
        return Batch(
            *(torch.from_numpy(a[rows]) for a in (self.obs, self.actions, self.rewards, self.next_obs, self.terminal))
        )


class DQNLearner(Generic[Q]):
    """An online Q-network, its target network and the Adam optimiser of the online one.

    Parameters
    ----------
    online : torch.nn.Module
        Q-network mapping observations (B, obs_size) to action values (B, n_actions); it is trained
        in place, and the target network starts as a copy of it.
    learning_rate : float
        Adam step size.
    max_grad_norm : float
        Gradient-norm clipping of each update.
    double_q : bool, optional
        Double DQN targets: the online network picks the next action, the target network values it.
        Otherwise the target network's largest value is used.

    Attributes
    ----------
    online, target : torch.nn.Module
        The trained network and the copy that the TD targets are computed with.
    optimiser : torch.optim.Adam
        Optimiser of ``online``'s parameters.
    """

    def __init__(self, online: Q, *, learning_rate: float, max_grad_norm: float, double_q: bool = False) -> None:
        self.online = online
        self.target = copy.deepcopy(online)
        self.optimiser = torch.optim.Adam(online.parameters(), lr=learning_rate)
        self.max_grad_norm = max_grad_norm
        self.double_q = double_q

    def update(self, batch: Batch, discount: float) -> float:
        """One gradient step of the online network on the Huber loss to the TD targets of ``batch``.

        Parameters
        ----------
        batch : Batch
            Transitions, typically :meth:`ReplayBuffer.sample`'s.
        discount : float
            Factor on the value of ``next_obs``: γ per step, or γ^k for a transition spanning k ticks.

        Returns
        -------
        float
            The loss before the step.
        """
        with torch.no_grad():
            if self.double_q:
                next_actions = self.online(batch.next_obs).argmax(dim=1, keepdim=True)
                next_values = self.target(batch.next_obs).gather(1, next_actions).squeeze(1)
            else:
                next_values = self.target(batch.next_obs).max(dim=1).values
            # Torch rounds a scalar factor to float32 and the mask is exactly 1 where the transition
            # bootstraps, so there the target is bit for bit rewards + discount * next_values.
            targets = batch.rewards + discount * (1.0 - batch.terminal) * next_values
        values = self.online(batch.obs).gather(1, batch.actions[:, None]).squeeze(1)
        loss = nn.functional.smooth_l1_loss(values, targets)
        self.optimiser.zero_grad()
        loss.backward()
        nn.utils.clip_grad_norm_(self.online.parameters(), self.max_grad_norm)
        self.optimiser.step()
        return loss.item()

    def update_target(self) -> None:
        """Copy the online network's weights into the target network."""
        self.target.load_state_dict(self.online.state_dict())
