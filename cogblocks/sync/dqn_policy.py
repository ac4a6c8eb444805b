"""The DQN L3 policy: a Q-network choosing the virtual oscillator's frequency increment every tick."""

from __future__ import annotations

from importlib import resources
from os import PathLike

import torch
from torch import nn

from cogblocks.sync.motion import ACTIONS, L3Context

__all__ = ["DQNPolicy", "L3QNetwork"]

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
