"""The reinforcement-learning corrector of the PoP of Amplification (appendix paper, section IV).

Blending a human movement with a reference changes where it ends. The corrector adds
``v_u = k_u · α ⊙ (p_h − p_a)`` to the altered velocity, with ``α ∈ {0, 1}³`` switching the
correction on or off per axis, chosen every 10 samples by a DQN from the state
``[p_h, p_a, v_h, v_a, horizon]``. The reward (16)–(17) and its constants (Algorithm 1 of the
paper's reference [17]) are here too, shared by the block and its training environment."""

from __future__ import annotations

import os
from importlib import resources
from typing import Any

import numpy as np
import torch
from torch import nn

from cogblocks.blocks.samples import plausible
from cogblocks.blocks.specs import COUNT, POSITION, VELOCITY
from cogblocks.sim import Block, Signal
from cogblocks.sim.params import finite_number, positive_int
from cogblocks.sim.reading import load_torch

__all__ = [
    "ACTIONS",
    "CorrectorNet",
    "NoCorrection",
    "RLCorrector",
    "STATE_SIZE",
    "corrector_state",
    "load_corrector",
    "reward_constants",
    "step_reward",
]

#: The 8 actions α ∈ {0, 1}³, in the prototype's order (none, single axes, pairs, all).
ACTIONS = np.array(
    [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [1, 0, 1], [0, 1, 1], [1, 1, 1]], dtype=np.float64
)
STATE_SIZE = 13
CORRECTOR_WEIGHTS = "corrector.pt"

# Fixed input scales of the Q-network (mm, mm/s, samples): inputs of order one, stored with the weights.
_STATE_SCALE = np.concatenate([np.full(6, 300.0), np.full(6, 1000.0), [200.0]])


def reward_constants(k_s: float, *, gamma: float = 0.99, sigma: float = 1e4, k_out: int = 200) -> tuple[float, float]:
    """The prize ``r_in`` and the punishment ``r_exit`` of eq. (17).

    With ``r_max = r_G_max = 0``: ``r_in = σ (1 − γ) / γ^k_s`` and
    ``r_exit = σ γ^(−k_out) − r_in (γ^(−k_out) − 1) / (1 − γ)``.

    Parameters
    ----------
    k_s : float
        Settling horizon in steps: entering the goal set within ``k_s`` steps and staying there
        gives a discounted return of at least ``sigma``.
    gamma : float
        Discount factor per step.
    sigma : float
        Threshold of the discounted return.
    k_out : int
        Steps over which leaving the goal set must not pay.

    Returns
    -------
    r_in, r_exit : float
        273.2 and −101 953 for ``k_s = 100`` and the defaults.
    """
    prize = sigma * (1.0 - gamma) / gamma**k_s
    punishment = sigma * gamma ** (-k_out) - prize * (gamma ** (-k_out) - 1.0) / (1.0 - gamma)
    return prize, punishment


def step_reward(
    p_h: np.ndarray,
    p_a: np.ndarray,
    v_h: np.ndarray,
    alpha: np.ndarray,
    was_inside: np.ndarray,
    r_in: Any,
    r_exit: Any,
    *,
    delta_pos: float = 20.0,
    v_goal: float = 0.1,
    k_r: float = 0.01,
    k_alpha: float = 10.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Reward (16)–(17) of one step, for a batch of episodes.

    ``r = −k_r ‖p_a − p_h‖ − k_α Σα`` plus ``r_in`` inside the goal set (``‖p_h − p_a‖ ≤ δ_pos`` and
    ``‖v_h‖ ≤ v_goal``: the human has stopped and the avatar is close) and ``r_exit`` on the step
    that leaves it.

    Parameters
    ----------
    p_h, p_a, v_h, alpha : numpy.ndarray, shape (..., 3)
        Positions (mm), human velocity (mm/s) and the action of the step.
    was_inside : numpy.ndarray of bool, shape (...)
        Whether the previous step was in the goal set.
    r_in, r_exit : float or numpy.ndarray
        Constants from :func:`reward_constants` (per episode if arrays).

    Returns
    -------
    reward : numpy.ndarray, shape (...)
    inside : numpy.ndarray of bool, shape (...)
    """
    distance = np.linalg.norm(p_h - p_a, axis=-1)
    inside = (distance <= delta_pos) & (np.linalg.norm(v_h, axis=-1) <= v_goal)
    reward = -k_r * distance - k_alpha * alpha.sum(axis=-1)
    reward = reward + np.where(inside, r_in, 0.0) + np.where(was_inside & ~inside, r_exit, 0.0)
    return reward, inside


def corrector_state(p_h: Any, p_a: Any, v_h: Any, v_a: Any, horizon: Any) -> np.ndarray:
    """The DQN's state ``[p_h, p_a, v_h, v_a, horizon]``, shape (..., 13), float32."""
    horizon = np.asarray(horizon, dtype=np.float64)[..., None]
    return np.concatenate([p_h, p_a, v_h, v_a, horizon], axis=-1).astype(np.float32)


class CorrectorNet(nn.Module):
    """Q-network of the corrector: state (13) → 128 ReLU → 128 ReLU → one value per action (8).

    The state is divided by fixed scales (300 mm, 1000 mm/s, 200 samples) stored as a buffer.
    """

    def __init__(self) -> None:
        super().__init__()
        self.register_buffer("scale", torch.as_tensor(_STATE_SCALE, dtype=torch.float32))
        self.layers = nn.Sequential(
            nn.Linear(STATE_SIZE, 128),
            nn.ReLU(),
            nn.Linear(128, 128),
            nn.ReLU(),
            nn.Linear(128, len(ACTIONS)),
        )

    def forward(self, state: torch.Tensor) -> torch.Tensor:
        """Action values, shape (..., 8), of states of shape (..., 13)."""
        return self.layers(state / self.scale)

    def act(self, state: np.ndarray) -> np.ndarray:
        """Greedy action indices of NumPy states (..., 13)."""
        with torch.no_grad():
            return self(torch.as_tensor(state, dtype=torch.float32)).argmax(dim=-1).numpy()


def load_corrector(path: str | os.PathLike | None = None) -> CorrectorNet:
    """Load a :class:`CorrectorNet` saved by ``python -m cogblocks.training.corrector``.

    Parameters
    ----------
    path : path-like, optional
        The checkpoint; the shipped ``cogblocks/data/weights/corrector.pt`` by default.
    """
    if path is None:
        with resources.as_file(resources.files("cogblocks.data") / "weights" / CORRECTOR_WEIGHTS) as p:
            checkpoint = torch.load(p, weights_only=True)
    else:
        checkpoint = load_torch(path, "corrector checkpoint", keys=("state_dict",))
    network = CorrectorNet()
    network.load_state_dict(checkpoint["state_dict"])
    network.eval()
    network.checkpoint = {k: v for k, v in checkpoint.items() if k != "state_dict"}
    return network


class _Corrector(Block):
    """Ports shared by every corrector, so that one can replace another in a diagram."""

    def __init__(self, period: float | None) -> None:
        super().__init__(period=period)
        # read in the update phase only: v_u of a tick uses the previous tick's positions, which is
        # what lets the loop blender → position → corrector → blender compile
        self.add_input("p_h", POSITION, feedthrough=False)
        self.add_input("p_a", POSITION, feedthrough=False)
        self.add_input("v_h", VELOCITY, feedthrough=False)
        self.add_input("v_a", VELOCITY, feedthrough=False)
        self.add_input("horizon", COUNT, feedthrough=False, default=0)
        self.add_output("v_u", VELOCITY)
        self.add_output("alpha", Signal(shape=(3,), unit="1"))


class NoCorrection(_Corrector):
    """The corrector that never corrects: ``v_u = 0``, ``α = 0`` (ports of :class:`RLCorrector`).

    Notes
    -----
    Bad data policy: the inputs are not read, so the outputs are zero whatever they carry.
    """

    def __init__(self, *, period: float | None = None) -> None:
        super().__init__(period)


class RLCorrector(_Corrector):
    """``v_u = k_u · α ⊙ (p_h − p_a)`` with α chosen every ``interval`` samples by a DQN (eq. 15).

    At the end of tick ``k`` the block stores ``p_h(k) − p_a(k)``, which ``v_u`` uses at tick
    ``k + 1``; when ``k + 1`` is a multiple of ``interval`` it also chooses α for the next
    ``interval`` ticks, greedily, from the state at tick ``k``. So α = 0 during the first
    ``interval`` ticks, like the blender's pass-through, and both change on the same ticks.

    Ports
    -----
    p_h, p_a : input, shape (3,), mm
        Human and altered positions.
    v_h, v_a : input, shape (3,), mm/s
        Human and altered velocities.
    horizon : input, int64, optional
        Expected end of the movement in samples (from the projector); 0 if unconnected.
    v_u : output, shape (3,), mm/s
        The correction term.
    alpha : output, shape (3,)
        The action in use.

    Parameters
    ----------
    network : CorrectorNet, optional
        The trained Q-network; the shipped one by default.
    gain : float
        ``k_u`` in 1/s (> 0; 6 as in the paper).
    interval : int
        Samples between two decisions (10).

    Notes
    -----
    Bad data policy: a non-finite or implausible (beyond 1 km or 1 km/s,
    :func:`~cogblocks.blocks.samples.plausible`) position keeps the last stored difference; such
    a state keeps the last action.
    """

    def __init__(
        self,
        network: CorrectorNet | None = None,
        *,
        gain: float = 6.0,
        interval: int = 10,
        period: float | None = None,
    ) -> None:
        super().__init__(period)
        self.network = load_corrector() if network is None else network
        if not isinstance(self.network, CorrectorNet):
            raise ValueError(f"RLCorrector: network must be a CorrectorNet, got {type(self.network).__name__}")
        self.gain = finite_number(self, "gain", gain, low=0.0, low_open=True)
        self.interval = positive_int(self, "interval", interval)
        self.add_state("gap", np.zeros(3))
        self.add_state("action", 0)

    def output(self, k: int) -> None:
        alpha = ACTIONS[self.action]
        self.alpha.value[...] = alpha
        np.multiply(self.gain * alpha, self.gap, out=self.v_u.value)

    def update(self, k: int) -> None:
        positions_ok = plausible(self.p_h.value) and plausible(self.p_a.value)
        if positions_ok:
            np.subtract(self.p_h.value, self.p_a.value, out=self.gap)
        deciding = (k // self.every + 1) % self.interval == 0
        if deciding and positions_ok and plausible(self.v_h.value) and plausible(self.v_a.value):
            state = corrector_state(self.p_h.value, self.p_a.value, self.v_h.value, self.v_a.value, self.horizon.value)
            self.action = int(self.network.act(state))
