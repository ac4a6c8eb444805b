"""Train the DQN L3 motion computer on randomised groups, and select it on the validation split.

Usage::

    python -m cogblocks.training.sync_dqn --randomised --seed 0 --out cogblocks/data/weights/sync_dqn.pt

Domain randomisation: ``slots`` groups are trained on at once, each in ``copies`` independently explored
episodes; a slot's group is drawn uniformly from the first ``train_pool`` groups of the *train* split of
:func:`~cogblocks.data.groups.random_groups` (sizes, graphs, gains, ω, assisted participant) and cut to
a window drawn uniformly in ``window`` seconds (from t = 0, where every group starts); when it ends the
slot draws the next group. The network sees :func:`~cogblocks.sync.dqn_policy.group_features`.

Reward: ``reward_scale * (d[k + 1] - d[k])`` with ``d = r_with - r_without`` the gain over the same group
without L2, run alongside (its ``r`` does not depend on the policy, so it is computed once per group).
The no-L2 trajectory takes no action, so the greedy policy is the one of the plain increment of ``r``;
but on a random group ``r`` itself swings by tenths as clusters form and break, and subtracting the
no-L2 swing leaves in the reward only what the reference changed: the regression targets carry far
less noise, and a pull that lowers ``r`` is paid for even when ``r`` is rising anyway.

Model selection (fixed before training, never on the test split): ``checks`` times during training
the greedy policy runs on the first ``validation_groups`` groups of the *validation* split, each cut to
``validation_seconds``, and the network kept is the one that lowers ``r`` on the fewest of them, then
the one with the highest mean change (%). Nothing here reads the test split.

Training runs on one thread with everything seeded (``torch.manual_seed``, one NumPy generator for
group draws, windows, exploration and replay), so a seed reproduces the weights exactly.
"""

from __future__ import annotations

import copy
import dataclasses
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import torch

from cogblocks.data.groups import SyncGroup, random_groups
from cogblocks.sync.dqn_policy import FEATURE_SIZE, L3QNetwork, group_features
from cogblocks.sync.motion import ACTIONS, HOLD_ACTION
from cogblocks.training.dqn import DQNLearner, ReplayBuffer
from cogblocks.training.sync_env import SyncEnv, order_parameter_without_l2

__all__ = ["RandomisedConfig", "RandomisedResult", "selection_key", "train_randomised", "validation_changes"]


@dataclass(frozen=True)
class RandomisedConfig:
    """Hyper-parameters of :func:`train_randomised`.

    Attributes
    ----------
    ticks : int
        Training ticks; every slot advances one tick per tick.
    slots : int
        Groups trained on at once.
    copies : int
        Independently explored episodes of each slot's group.
    window : tuple of float
        Range (s) of the uniform draw of an episode's length (capped at the group's duration).
    train_pool : int
        Groups of the train split that slots draw from.
    data_seed : int
        Seed of :func:`random_groups` for the train and validation splits.
    validation_groups : int
        Groups of the validation split the selection runs on.
    validation_seconds : float
        Cap on a validation group's duration.
    checks : int
        Greedy evaluations on the validation groups, evenly spaced over training.
    gamma, reward_scale, learning_rate, batch_size, buffer_size, learning_starts, train_every, target_every,
    eps_start, eps_end, eps_decay_fraction, max_grad_norm, double_q
        As in :class:`~cogblocks.training.sync_dqn.DQNConfig`.
    """

    ticks: int = 40_000
    slots: int = 8
    copies: int = 4
    window: tuple[float, float] = (20.0, 60.0)
    train_pool: int = 2_000
    data_seed: int = 0
    validation_groups: int = 30
    validation_seconds: float = 30.0
    checks: int = 8
    gamma: float = 0.99
    reward_scale: float = 100.0
    learning_rate: float = 3e-4
    batch_size: int = 256
    buffer_size: int = 500_000
    learning_starts: int = 5_000
    train_every: int = 2
    target_every: int = 1_000
    eps_start: float = 1.0
    eps_end: float = 0.05
    eps_decay_fraction: float = 0.4
    max_grad_norm: float = 10.0
    double_q: bool = True


QUICK_RANDOMISED = RandomisedConfig(
    ticks=3_000,
    slots=4,
    copies=2,
    train_pool=50,
    validation_groups=8,
    validation_seconds=10.0,
    checks=2,
    learning_starts=500,
)
"""Smoke-test settings of ``--randomised --quick``: well under a minute."""


@dataclass
class RandomisedResult:
    """Outcome of :func:`train_randomised`.

    Attributes
    ----------
    network : L3QNetwork
        The selected network (input :func:`group_features`).
    history : list of dict
        One entry per validation check: ``tick``, ``epsilon``, ``loss``, ``lowered`` (groups whose ``r`` is
        lowered), ``mean_change_pct``, ``worst_change_pct`` and ``cpu_s`` (CPU time so far).
    best : int
        Index in ``history`` of the selected network.
    groups_drawn : list of SyncGroup
        Every training episode's group, window applied, in the order drawn.
    """

    network: L3QNetwork
    history: list[dict]
    best: int
    groups_drawn: list[SyncGroup]


def selection_key(change_pct: np.ndarray) -> tuple[int, float]:
    """Smaller is better: the number of groups whose ``r`` is lowered, then minus the mean change (%)."""
    change_pct = np.asarray(change_pct, dtype=float)
    return int(np.sum(change_pct < 0.0)), -float(change_pct.mean())


def _r_without(group: SyncGroup) -> np.ndarray:
    """The order parameter of ``group`` without L2 at every tick ``0 ... T/dt``."""
    env = SyncEnv.from_group(group, l2=False)
    r = [env.r[0]]
    while not env.done:
        r.append(env.step(np.array([HOLD_ACTION]))[1][0])
    return np.array(r)


class _Slot:
    """One group's batch of training episodes, with the features and the no-L2 trajectory it needs."""

    def __init__(self, group: SyncGroup, copies: int, *, with_reward: bool = True) -> None:
        self.group = group
        self.env = SyncEnv.from_group(group, copies)
        self.omega_init = self.env.model.omega.mean(axis=-1)
        self.r_without = _r_without(group) if with_reward else None

    def features(self) -> np.ndarray:
        env = self.env
        return group_features(env.theta_l3, env.theta, env.model.assisted, env.lam, env.omega_prev, self.omega_init)

    def gain(self) -> np.ndarray:
        """``d[k] = r_with[k] - r_without[k]`` of every copy at the current tick."""
        return self.env.r - self.r_without[self.env.k]


def validation_changes(network: L3QNetwork, groups: Sequence[SyncGroup]) -> np.ndarray:
    """Change (%) of the mean ``r`` with the greedy ``network`` against without L2, one group each.

    All groups run in lockstep, one forward pass per tick over the groups still running; the result is
    :func:`~cogblocks.training.sync_env.evaluate`'s ``change_pct`` with a :class:`DQNPolicy` of ``network``.
    """
    slots = [_Slot(group, 1, with_reward=False) for group in groups]
    with torch.no_grad():
        while running := [slot for slot in slots if not slot.env.done]:
            obs = np.concatenate([slot.features() for slot in running])
            actions = network(torch.from_numpy(obs.astype(np.float32))).argmax(dim=1).numpy()
            for slot, action in zip(running, actions, strict=True):
                slot.env.step(action[None])
    r_without = np.array([order_parameter_without_l2(group) for group in groups])
    r_with = np.array([slot.env.mean_order_parameter[0] for slot in slots])
    return 100.0 * (r_with - r_without) / r_without


def train_randomised(
    config: RandomisedConfig, seed: int, *, log: Callable[[str], None] | None = print
) -> RandomisedResult:
    """Train an :class:`L3QNetwork` on :func:`group_features` over randomised train groups.

    Parameters
    ----------
    config : RandomisedConfig
        Hyper-parameters.
    seed : int
        Seeds the initial weights and the generator of group draws, windows, exploration and replay.
    log : callable, optional
        Receives one line per validation check; ``None`` is silent.

    Returns
    -------
    RandomisedResult
        The network selected on the validation split and the checks' history.
    """
    threads = torch.get_num_threads()
    # Reductions may be split differently across threads, so one thread is what makes a seed reproducible.
    torch.set_num_threads(1)
    try:
        return _train(config, seed, log)
    finally:
        torch.set_num_threads(threads)


def _train(config: RandomisedConfig, seed: int, log: Callable[[str], None] | None) -> RandomisedResult:
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    pool = random_groups(config.train_pool, "train", config.data_seed)
    validation = [
        dataclasses.replace(g, duration=min(g.duration, config.validation_seconds))
        for g in random_groups(config.validation_groups, "validation", config.data_seed)
    ]
    learner = DQNLearner(
        L3QNetwork(FEATURE_SIZE),
        learning_rate=config.learning_rate,
        max_grad_norm=config.max_grad_norm,
        double_q=config.double_q,
    )
    online = learner.online
    buffer = ReplayBuffer(config.buffer_size, FEATURE_SIZE)
    drawn: list[SyncGroup] = []

    def draw() -> _Slot:
        group = pool[int(rng.integers(len(pool)))]
        window = round(float(rng.uniform(*config.window)), 2)
        group = dataclasses.replace(group, duration=min(group.duration, window))
        drawn.append(group)
        return _Slot(group, config.copies)

    slots = [draw() for _ in range(config.slots)]
    obs = np.concatenate([slot.features() for slot in slots])
    decay_ticks = max(1, round(config.eps_decay_fraction * config.ticks))
    check_ticks = {round(i * config.ticks / config.checks) for i in range(1, config.checks + 1)}
    history: list[dict] = []
    best_key, best_state, best_check = (np.inf, np.inf), copy.deepcopy(online.state_dict()), 0
    losses: list[float] = []
    gradient_steps, started_cpu = 0, time.process_time()
    for tick in range(1, config.ticks + 1):
        epsilon = config.eps_end + (config.eps_start - config.eps_end) * max(0.0, 1.0 - tick / decay_ticks)
        with torch.no_grad():
            actions = online(torch.from_numpy(obs.astype(np.float32))).argmax(dim=1).numpy()
        explore = rng.random(len(actions)) < epsilon
        actions = np.where(explore, rng.integers(len(ACTIONS), size=len(actions)), actions)

        rewards, next_obs = [], []
        for i, slot in enumerate(slots):
            before = slot.gain()
            slot.env.step(actions[i * config.copies : (i + 1) * config.copies])
            rewards.append(config.reward_scale * (slot.gain() - before))
            next_obs.append(slot.features())
            if slot.env.done:
                slots[i] = draw()
        # Windows truncate, never terminate: every transition bootstraps.
        buffer.add(obs, actions, np.concatenate(rewards), np.concatenate(next_obs), np.zeros(len(actions), dtype=bool))
        obs = np.concatenate([slot.features() for slot in slots])

        if buffer.size >= config.learning_starts and tick % config.train_every == 0:
            losses.append(learner.update(buffer.sample(rng, config.batch_size), config.gamma))
            gradient_steps += 1
            if gradient_steps % config.target_every == 0:
                learner.update_target()

        if tick in check_ticks:
            change = validation_changes(online, validation)
            key = selection_key(change)
            record = {
                "tick": tick,
                "epsilon": epsilon,
                "loss": float(np.mean(losses)) if losses else float("nan"),
                "lowered": key[0],
                "mean_change_pct": float(change.mean()),
                "worst_change_pct": float(change.min()),
                "cpu_s": time.process_time() - started_cpu,
            }
            if key < best_key:
                best_key, best_state, best_check = key, copy.deepcopy(online.state_dict()), len(history)
            history.append(record)
            if log is not None:
                log(
                    f"tick {tick}/{config.ticks}  eps {epsilon:.3f}  loss {record['loss']:.4f}  validation: lowered "
                    f"{key[0]}/{len(validation)}, mean {record['mean_change_pct']:+.3f} %, worst "
                    f"{record['worst_change_pct']:+.3f} %  (CPU {record['cpu_s']:.0f} s)"
                )
            losses = []
    online.load_state_dict(best_state)
    return RandomisedResult(network=online, history=history, best=best_check, groups_drawn=drawn)
