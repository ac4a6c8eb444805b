"""The DQN L3 policy: a Q-network choosing the virtual oscillator's frequency increment every tick.

Two observations exist, told apart by the network's input size:

* the deliverable's 3 numbers ``[angle(q), 1 − |q|, ω_prev]`` (:func:`~cogblocks.sync.motion.l3_observation`,
  ``OBS_SIZE``), the input of the network trained on Table 2's groups;
* :func:`group_features` (``FEATURE_SIZE`` numbers), the input of the network trained on randomised
  groups (:mod:`cogblocks.training.sync_dqn_random`): relative, scale-free quantities that carry over
  from one group to another, and that say where the participant is, not only where the reference is.
"""

from __future__ import annotations

from importlib import resources
from os import PathLike

import numpy as np
import torch
from torch import nn

from cogblocks.sync.motion import ACTIONS, L3Context

__all__ = ["DQNPolicy", "FEATURE_SIZE", "L3QNetwork", "NumpyDQNPolicy", "OBS_SIZE", "group_features"]

OBS_SIZE = 3
FEATURE_SIZE = 10


def group_features(
    theta_l3: np.ndarray | float,
    theta: np.ndarray,
    assisted: int,
    lam: np.ndarray | float,
    omega_prev: np.ndarray | float,
    omega_init: np.ndarray | float,
) -> np.ndarray:
    """Observation of the randomised DQN at one tick, shape (..., FEATURE_SIZE); broadcasts over leading axes.

    With ``ψ`` and ``R`` the angle and length of the others' mean ``mean_{j≠a} exp(i θ_j)``,
    ``θ_L0 = θ_a`` and ``θ_L3`` the reference:
    ``[sin, cos(θ_L3 − ψ), sin, cos(θ_L0 − ψ), sin, cos(θ_L3 − θ_L0), R, λ, ω_prev − ω_init, 1/N]``.

    Angles enter as sine and cosine (no jump at ±π); ``ω_prev − ω_init`` is the reference's frequency
    relative to the group's mean natural frequency (the oscillator's start), so that the absolute tempo,
    which differs from group to group, does not; ``1/N`` is the assisted participant's weight in ``r``.
    Memoryless: the same context gives the same features, which keeps a diagram's snapshot exact.
    """
    theta = np.asarray(theta, dtype=float)
    n = theta.shape[-1]
    others = np.flatnonzero(np.arange(n) != assisted)
    phases = theta[..., others]
    m = len(others)
    c, s = np.cos(phases).sum(axis=-1) / m, np.sin(phases).sum(axis=-1) / m
    psi = np.arctan2(s, c)
    theta_l3 = np.asarray(theta_l3, dtype=float)
    theta_l0 = theta[..., assisted]
    features = np.empty(psi.shape + (FEATURE_SIZE,))
    for column, angle in ((0, theta_l3 - psi), (2, theta_l0 - psi), (4, theta_l3 - theta_l0)):
        features[..., column] = np.sin(angle)
        features[..., column + 1] = np.cos(angle)
    features[..., 6] = np.hypot(c, s)
    features[..., 7] = lam
    features[..., 8] = np.asarray(omega_prev, dtype=float) - omega_init
    features[..., 9] = 1.0 / n
    return features


class L3QNetwork(nn.Module):
    """Q-network of the L3 policy: observation -> 128 -> 64 -> one value per action (11), ReLU.

    Parameters
    ----------
    obs_size : int
        ``OBS_SIZE`` (3, the deliverable's observation) or ``FEATURE_SIZE`` (:func:`group_features`).
        The observation is used as is, without normalisation.
    """

    def __init__(self, obs_size: int = OBS_SIZE) -> None:
        super().__init__()
        if obs_size not in (OBS_SIZE, FEATURE_SIZE):
            raise ValueError(f"L3QNetwork: obs_size must be {OBS_SIZE} or {FEATURE_SIZE}, got {obs_size!r}")
        self.obs_size = obs_size
        self.layers = nn.Sequential(
            nn.Linear(obs_size, 128),
            nn.ReLU(),
            nn.Linear(128, 64),
            nn.ReLU(),
            nn.Linear(64, len(ACTIONS)),
        )

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        """Action values, shape (..., 11), of observations of shape (..., obs_size)."""
        return self.layers(obs)


class DQNPolicy:
    """Greedy policy of a trained :class:`L3QNetwork`.

    Parameters
    ----------
    network : L3QNetwork
        Trained network; switched to evaluation mode. Its input size chooses the observation: the
        context's 3-number ``obs`` or :func:`group_features` of the context.
    """

    def __init__(self, network: L3QNetwork) -> None:
        self.network = network.eval()
        self.omega_init = float("nan")

    @classmethod
    def from_file(cls, path: str | PathLike[str]) -> DQNPolicy:
        """Load a ``state_dict`` saved by :mod:`cogblocks.training.sync_dqn` (either observation)."""
        from cogblocks.sim.reading import FileFormatError, load_torch

        state = load_torch(path, "DQN policy state dict", keys=("layers.0.weight",))
        network = L3QNetwork(obs_size=state["layers.0.weight"].shape[1])
        try:
            network.load_state_dict(state)
        except RuntimeError as error:
            raise FileFormatError(f"{path}: not a DQN policy of this network: {str(error).splitlines()[0]}") from None
        return cls(network)

    @classmethod
    def default(cls, weights: str = "sync_dqn.pt") -> DQNPolicy:
        """Policy with weights shipped in ``cogblocks/data/weights``.

        ``"sync_dqn.pt"`` (the default) is the network trained on randomised groups and selected on the
        validation split; ``"sync_dqn_table2.pt"`` the deliverable's 3-input network trained and selected
        on Table 2's three groups (``python -m cogblocks.training.sync_dqn --seed 0`` without ``--randomised``).
        """
        with resources.as_file(resources.files("cogblocks.data") / "weights" / weights) as path:
            return cls.from_file(path)

    def reset(self, omega_init: float) -> None:
        """Remember where the oscillator starts (the group's mean natural frequency), the features' origin."""
        self.omega_init = float(omega_init)

    def observation(self, context: L3Context) -> np.ndarray:
        """What the network sees at this tick."""
        if self.network.obs_size == OBS_SIZE:
            return context.obs
        if context.assisted is None:
            raise ValueError("DQNPolicy: this network's features need the context's assisted index")
        return group_features(
            context.theta_l3, context.theta, context.assisted, context.lam, context.omega_prev, self.omega_init
        )

    def act(self, context: L3Context) -> int:
        """Action with the highest value for this tick's observation."""
        with torch.no_grad():
            values = self.network(torch.as_tensor(self.observation(context), dtype=torch.float32))
        return int(values.argmax())

    def act_rows(self, context: L3Context) -> np.ndarray:
        """The action of every run of a batch: ``context``'s fields hold one row per run; one forward pass."""
        with torch.no_grad():
            values = self.network(torch.as_tensor(self.observation(context), dtype=torch.float32))
        return values.argmax(dim=-1).numpy()

    def predictor(self) -> NumpyDQNPolicy:
        """A copy for predictions that run the policy ahead many times per tick (the network in float64 NumPy).

        Several times cheaper per call than torch on one observation, it chooses the same action except where
        two action values are within rounding of each other.
        """
        return NumpyDQNPolicy(self)


class NumpyDQNPolicy(DQNPolicy):
    """:class:`DQNPolicy` with the network's layers evaluated in float64 NumPy (see :meth:`DQNPolicy.predictor`).

    A prediction that runs the policy ahead tick by tick (:class:`~cogblocks.sync.shielded.ShieldedMotion`) asks
    it hundreds of times per decision, where torch's per-call overhead on one observation dominates.
    """

    def __init__(self, policy: DQNPolicy) -> None:
        super().__init__(policy.network)
        linear = [layer for layer in self.network.layers if isinstance(layer, nn.Linear)]
        self.weights = [layer.weight.detach().double().numpy().T.copy() for layer in linear]
        self.biases = [layer.bias.detach().double().numpy().copy() for layer in linear]
        self.omega_init = policy.omega_init

    def act(self, context: L3Context) -> int:
        """Action with the highest value for this tick's observation."""
        return int(self.act_rows(context))

    def act_rows(self, context: L3Context) -> np.ndarray:
        """The action of every run of a batch (``context``'s fields one row per run), in float64 NumPy."""
        x = self.observation(context)
        last = len(self.weights) - 1
        for i, (weight, bias) in enumerate(zip(self.weights, self.biases, strict=True)):
            x = x @ weight + bias
            if i < last:
                x = np.maximum(x, 0.0)
        return np.argmax(x, axis=-1)
