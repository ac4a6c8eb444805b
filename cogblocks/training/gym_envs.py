"""The training environments as Gymnasium environments (optional extra ``rl``).

* ``cogblocks/SyncL3-v0`` (:class:`SyncL3Env`): the L3 motion computer of the PoP of Social
  Connectedness in the closed loop with the L2 blender, :class:`~cogblocks.training.sync_env.SyncEnv`
  with one episode. Observation ``[angle(q), 1 − |q|, ω_L3[k−1]]`` (float32), 11 actions (frequency
  increments), reward ``reward_scale · (r[k+1] − r[k])`` as in the project's trainer. Each reset
  draws one of the groups (Table 2's by default) with the environment's generator; episodes end by
  time limit (``truncated``), never ``terminated``: the observation carries no clock.
* ``cogblocks/CorrectorAmplification-v0`` (:class:`CorrectorEnv`): the RL corrector of the PoP of
  Amplification, :class:`~cogblocks.training.amplification_env.AmplificationEnv` with one episode.
  Observation: the corrector's 13-number state; 8 actions; reward: the discounted rewards (16)–(17)
  of one decision interval. ``terminated`` when the altered hand leaves the goal set before the
  last tick, ``truncated`` at the last tick. Each reset draws one of the recorded movements.
* :class:`SyncL3VectorEnv`: ``num_envs`` episodes of one group advanced together by the batched
  :class:`~cogblocks.training.sync_env.SyncEnv` (``gymnasium.make_vec("cogblocks/SyncL3-v0",
  num_envs=…, vectorization_mode="vector_entry_point")``); all episodes end on the same tick and
  restart on the next step (``AutoresetMode.NEXT_STEP``).

Importing this module registers the ids; ``import cogblocks`` does not import gymnasium.
``gymnasium.make("cogblocks.training.gym_envs:cogblocks/SyncL3-v0")`` imports and makes in one call.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv

from cogblocks.amplification.corrector import ACTIONS as CORRECTOR_ACTIONS
from cogblocks.amplification.corrector import STATE_SIZE
from cogblocks.data.groups import TABLE2, SyncGroup
from cogblocks.sync.model import DT, SyncModel
from cogblocks.sync.motion import ACTIONS, OMEGA_L3_LIMIT
from cogblocks.training.amplification_env import AmplificationEnv, Episodes
from cogblocks.training.sync_env import SyncEnv

__all__ = ["SYNC_ID", "CORRECTOR_ID", "CorrectorEnv", "SyncL3Env", "SyncL3VectorEnv", "register_envs"]

SYNC_ID = "cogblocks/SyncL3-v0"
CORRECTOR_ID = "cogblocks/CorrectorAmplification-v0"

#: Bounds of the L3 observation: angle of q, 1 − |q|, the previous L3 frequency (rad/s).
_SYNC_LOW = np.array([-np.pi, 0.0, -OMEGA_L3_LIMIT], dtype=np.float32)
_SYNC_HIGH = np.array([np.pi, 1.0, OMEGA_L3_LIMIT], dtype=np.float32)


def _sync_observation_space(shape: tuple[int, ...] = ()) -> spaces.Box:
    low = np.broadcast_to(_SYNC_LOW, (*shape, 3))
    high = np.broadcast_to(_SYNC_HIGH, (*shape, 3))
    return spaces.Box(low=low, high=high, dtype=np.float32)


def _capped(group: SyncGroup, episode_seconds: float | None) -> SyncGroup:
    if episode_seconds is None or group.duration <= episode_seconds:
        return group
    return SyncGroup(group.name, group.n, group.gain, group.omega, group.assisted, float(episode_seconds))


class SyncL3Env(gymnasium.Env):
    """One closed-loop episode of the L3 motion computer (see the module docstring).

    Parameters
    ----------
    groups : sequence of SyncGroup, optional
        The groups a reset draws from (Table 2's by default); ``reset(options={"group": i})`` picks one.
    episode_seconds : float, optional
        Cap on a group's duration (short episodes for smoke tests).
    reward_scale : float
        Factor on the order-parameter increment (the project's trainer uses 100).
    """

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(
        self,
        groups: Sequence[SyncGroup] | None = None,
        *,
        episode_seconds: float | None = None,
        reward_scale: float = 100.0,
    ) -> None:
        self.groups = [_capped(g, episode_seconds) for g in (groups or list(TABLE2.values()))]
        if not self.groups:
            raise ValueError("SyncL3Env: groups must not be empty")
        self.reward_scale = float(reward_scale)
        self.observation_space = _sync_observation_space()
        self.action_space = spaces.Discrete(len(ACTIONS))
        self._env: SyncEnv | None = None
        self._group = 0

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        if options and "group" in options:
            self._group = int(options["group"])
        else:
            self._group = int(self.np_random.integers(len(self.groups)))
        self._env = SyncEnv.from_group(self.groups[self._group])
        obs = self._env.reset()[0]
        return obs.astype(np.float32), {"group": self.groups[self._group].name, "r": float(self._env.r[0])}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        if self._env is None:
            raise RuntimeError("SyncL3Env: call reset() before step()")
        r_before = float(self._env.r[0])
        obs, r, done = self._env.step(np.array([int(action)]))
        info: dict[str, Any] = {"r": float(r[0])}
        if done:
            info["mean_order_parameter"] = float(self._env.mean_order_parameter[0])
        reward = self.reward_scale * (float(r[0]) - r_before)
        return obs[0].astype(np.float32), reward, False, bool(done), info


class SyncL3VectorEnv(VectorEnv):
    """``num_envs`` episodes of one group, advanced together by the batched :class:`SyncEnv`.

    Parameters
    ----------
    num_envs : int
        Episodes in the batch.
    group : SyncGroup, optional
        Table 2's Group 3 by default.
    episode_seconds, reward_scale : see :class:`SyncL3Env`.
    """

    metadata: dict[str, Any] = {"render_modes": [], "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(
        self,
        num_envs: int = 1,
        group: SyncGroup | None = None,
        *,
        episode_seconds: float | None = None,
        reward_scale: float = 100.0,
    ) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
            raise ValueError(f"SyncL3VectorEnv: num_envs must be an integer >= 1, got {num_envs!r}")
        self.num_envs = num_envs
        self.group = _capped(group or TABLE2[3], episode_seconds)
        self.reward_scale = float(reward_scale)
        self.single_observation_space = _sync_observation_space()
        self.single_action_space = spaces.Discrete(len(ACTIONS))
        self.observation_space = _sync_observation_space((num_envs,))
        self.action_space = spaces.MultiDiscrete(np.full(num_envs, len(ACTIONS)))
        model = SyncModel.from_group(self.group, dt=DT)
        batched = SyncModel(
            np.tile(model.omega, (num_envs, 1)), model.gain, model.adjacency, model.assisted, model.dt, model.blender
        )
        self._env = SyncEnv(batched, round(self.group.duration / DT))
        self._needs_reset = False

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)  # the dynamics are deterministic: the seed only seeds the spaces' samplers
        self._needs_reset = False
        return self._env.reset().astype(np.float32), {}

    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict]:
        n = self.num_envs
        if self._needs_reset:  # NEXT_STEP autoreset: this step only restarts the episodes
            obs, _ = self.reset()
            return obs, np.zeros(n), np.zeros(n, dtype=bool), np.zeros(n, dtype=bool), {}
        r_before = self._env.r.copy()
        obs, r, done = self._env.step(np.asarray(actions, dtype=np.int64))
        self._needs_reset = bool(done)
        truncated = np.full(n, bool(done))
        info: dict[str, Any] = {}
        if done:  # vector-env convention: the values and, under "_name", which episodes have one
            info = {"mean_order_parameter": self._env.mean_order_parameter.copy(), "_mean_order_parameter": truncated}
        return obs.astype(np.float32), self.reward_scale * (r - r_before), np.zeros(n, dtype=bool), truncated, info


class CorrectorEnv(gymnasium.Env):
    """One episode of the RL corrector on a recorded movement (see the module docstring).

    Parameters
    ----------
    episodes : Episodes, optional
        Movements recorded with :func:`~cogblocks.training.amplification_env.record_episodes`; by
        default the training movements of the shipped setup
        (:func:`~cogblocks.training.corrector.training_episodes`, about a minute to record).
    gain, interval, gamma : see :class:`AmplificationEnv`.
    """

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(
        self, episodes: Episodes | None = None, *, gain: float = 6.0, interval: int = 10, gamma: float = 0.99
    ) -> None:
        if episodes is None:
            from cogblocks.training.corrector import training_episodes

            episodes = training_episodes()
        self._env = AmplificationEnv(episodes, gain=gain, interval=interval, gamma=gamma)
        self.observation_space = spaces.Box(-np.inf, np.inf, shape=(STATE_SIZE,), dtype=np.float32)
        self.action_space = spaces.Discrete(len(CORRECTOR_ACTIONS))
        self._started = False

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        n = len(self._env.episodes)
        row = int(options["movement"]) if options and "movement" in options else int(self.np_random.integers(n))
        state = self._env.reset(np.array([row]))
        self._started = True
        return state[0], {"movement": row}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        if not self._started or self._env.done[0]:
            raise RuntimeError("CorrectorEnv: call reset() before step()")
        state, reward, done = self._env.step(np.array([int(action)]))
        at_end = self._env.t >= self._env.n_steps - 1
        info = {"distance_mm": float(self._env.final_distance()[0])}
        return state[0], float(reward[0]), bool(done[0]) and not at_end, at_end, info


def register_envs() -> None:
    """Register :data:`SYNC_ID` (with its vector entry point) and :data:`CORRECTOR_ID` (idempotent)."""
    registry = gymnasium.envs.registration.registry
    if SYNC_ID not in registry:
        gymnasium.register(
            SYNC_ID,
            entry_point=f"{__name__}:SyncL3Env",
            vector_entry_point=f"{__name__}:SyncL3VectorEnv",
        )
    if CORRECTOR_ID not in registry:
        gymnasium.register(CORRECTOR_ID, entry_point=f"{__name__}:CorrectorEnv")


register_envs()
