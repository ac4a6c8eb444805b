"""Train the DQN L3 motion computer of the PoP of Social Connectedness in the closed loop with the L2 blender.

Usage::

    python -m cogblocks.training.sync_dqn --seed 0 --out cogblocks/data/weights/sync_dqn.pt [--episodes N] [--quick]

Standard DQN: ε-greedy exploration decaying linearly, a replay buffer, a target network copied at a
fixed interval, Adam on the Huber loss, with Double-DQN targets. The environment is
:class:`~cogblocks.training.sync_env.SyncEnv` with the deliverable's blender, on the three groups of
Table 2. Several copies of each group run in lockstep; the 300 s groups (2 and 3) run one episode per
*round* while the 10 s group 1 restarts every 10 s. Episodes that reach their time limit are truncated,
not terminated: the last transition bootstraps like any other, since the observation carries no clock.

Reward: ``reward_scale * (r[k + 1] - r[k])``, the increment of the order parameter with L2. Its
discounted return is ``(1 - γ) * G_r - r[k]`` with ``G_r`` the discounted return of ``r`` itself: the
greedy policy is the same, but the current order parameter, which the 3-number observation cannot
see and which dominates ``G_r``, is subtracted, so the regression targets carry far less noise.
γ = 0.99 looks about 1 s ahead, the time scale of the blender's threshold (1/κ⁺ = 1 s, 1/κ⁻ = 0.4 s).

Model selection: the closed loop is chaotic in the policy (two networks with close action values can
end a 300 s episode far apart), so the training curve alone says little. ``checks_per_episode`` times
per round the greedy policy is evaluated with :func:`~cogblocks.training.sync_env.evaluate` on the
three groups, and the network whose worst group is best relative to Table 3's improvements is kept.
A candidate is dropped as soon as one group rules it out, so most checks cost one 10 s episode.

Everything is seeded (``torch.manual_seed`` for the initial weights, one NumPy ``Generator`` for
exploration and replay sampling) and runs on one thread, so a seed reproduces the weights exactly.
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from cogblocks.data.groups import TABLE2, TABLE3_CHANGE_PCT, SyncGroup
from cogblocks.sync import DQNPolicy, SyncModel
from cogblocks.sync.dqn_policy import OBS_SIZE, L3QNetwork
from cogblocks.sync.model import DT
from cogblocks.sync.motion import ACTIONS
from cogblocks.training.dqn import DQNLearner, ReplayBuffer
from cogblocks.training.sync_env import SyncEnv, evaluate

__all__ = ["DQNConfig", "TrainingResult", "main", "train"]


@dataclass(frozen=True)
class DQNConfig:
    """Hyper-parameters of :func:`train`.

    Attributes
    ----------
    episodes : int
        Rounds of training: one episode of each copy of the longest group (shorter groups restart
        meanwhile).
    copies : int
        Parallel episodes of each group, explored independently.
    episode_seconds : float or None
        Cap on every group's duration, for training and model selection alike (smoke tests).
    gamma : float
        Discount per 10 ms tick.
    reward_scale : float
        Factor on the order-parameter increment, to bring action values to order 1.
    learning_rate : float
        Adam step size.
    batch_size : int
        Transitions per gradient step.
    buffer_size : int
        Replay capacity in transitions.
    learning_starts : int
        Transitions stored before the first gradient step.
    train_every : int
        Ticks between gradient steps.
    target_every : int
        Gradient steps between copies of the online network into the target network.
    eps_start, eps_end : float
        Exploration rate at the start and after the decay.
    eps_decay_fraction : float
        Fraction of all ticks over which ε decays linearly.
    max_grad_norm : float
        Gradient-norm clipping.
    double_q : bool
        Double DQN targets: the online network picks the next action, the target network values it.
    checks_per_episode : int
        Greedy evaluations (model-selection candidates) per round.
    """

    episodes: int = 4
    copies: int = 4
    episode_seconds: float | None = None
    gamma: float = 0.99
    reward_scale: float = 100.0
    learning_rate: float = 1e-4
    batch_size: int = 256
    buffer_size: int = 1_000_000
    learning_starts: int = 10_000
    train_every: int = 4
    target_every: int = 2_000
    eps_start: float = 1.0
    eps_end: float = 0.05
    eps_decay_fraction: float = 0.5
    max_grad_norm: float = 10.0
    double_q: bool = True
    checks_per_episode: int = 30


QUICK_CONFIG = DQNConfig(
    episodes=2, copies=2, episode_seconds=20.0, learning_starts=1_000, buffer_size=50_000, checks_per_episode=3
)
"""Smoke-test settings of ``--quick``: a minute of training on 20 s episodes."""


@dataclass
class TrainingResult:
    """Outcome of :func:`train`.

    Attributes
    ----------
    network : L3QNetwork
        Selected network (best worst-group improvement relative to Table 3).
    history : list of dict
        One entry per greedy evaluation: ``episode`` (rounds done, fractional), ``epsilon``, ``loss``
        (mean Huber loss since the previous evaluation), ``change_pct`` of the groups evaluated (the
        rest are skipped once the candidate cannot be selected) and ``score``, their worst ratio to
        Table 3's improvement.
    best : int
        Index in ``history`` of the selected network.
    """

    network: L3QNetwork
    history: list[dict]
    best: int


def _grouped_envs(groups: Sequence[SyncGroup], copies: int, episode_seconds: float | None) -> list[SyncEnv]:
    """One batched environment per (size, assisted index, duration), holding ``copies`` of each group."""
    buckets: dict[tuple[int, int, float], list[SyncGroup]] = {}
    for group in groups:
        duration = group.duration if episode_seconds is None else min(group.duration, episode_seconds)
        buckets.setdefault((group.n, group.assisted, duration), []).append(group)
    envs = []
    for (_, _, duration), members in buckets.items():
        template = SyncModel.from_group(members[0])
        model = dataclasses.replace(
            template,
            omega=np.repeat(np.array([g.omega for g in members]), copies, axis=0),
            gain=np.repeat(np.array([g.gain for g in members]), copies),
        )
        envs.append(SyncEnv(model, round(duration / DT)))
    return envs


def _capped(group: SyncGroup, episode_seconds: float | None) -> SyncGroup:
    if episode_seconds is None or group.duration <= episode_seconds:
        return group
    return dataclasses.replace(group, duration=episode_seconds)


def _evaluate_until_worse(
    policy: DQNPolicy, groups: dict[int, SyncGroup], best_score: float, episode_seconds: float | None
) -> dict[int, float]:
    """Improvement (%) per group, shortest group first, stopping once one cannot beat ``best_score``.

    The selection score is a minimum over groups, so a group at or below the best score so far rules the
    network out: the remaining (300 s) evaluations are skipped, and the score of the groups evaluated
    bounds the full one from above, which keeps the selection exactly as with every group evaluated.
    """
    change_pct: dict[int, float] = {}
    for number, group in sorted(groups.items(), key=lambda item: item[1].duration):
        change_pct[number] = evaluate(policy, _capped(group, episode_seconds))["change_pct"]
        if _selection_score(change_pct) <= best_score:
            break
    return change_pct


def _selection_score(change_pct: dict[int, float]) -> float:
    """Worst ratio over the groups of the improvement to Table 3's: above 1 beats the deliverable on each."""
    return min(change_pct[g] / TABLE3_CHANGE_PCT[g] for g in change_pct)


def train(
    config: DQNConfig,
    seed: int,
    *,
    groups: dict[int, SyncGroup] | None = None,
    log: Callable[[str], None] | None = print,
) -> TrainingResult:
    """Train an :class:`L3QNetwork` with DQN in the closed loop with the L2 blender.

    Parameters
    ----------
    config : DQNConfig
        Hyper-parameters.
    seed : int
        Seeds the initial weights (``torch.manual_seed``) and the NumPy generator of exploration and
        replay sampling. Training runs on one thread, restored afterwards.
    groups : dict of int to SyncGroup, optional
        Training and selection groups keyed like Table 3's improvements; defaults to Table 2's.
    log : callable, optional
        Receives one line per greedy evaluation; ``None`` is silent.

    Returns
    -------
    TrainingResult
        The selected network and the evaluation history.
    """
    threads = torch.get_num_threads()
    # Reductions may be split differently across threads, so one thread is what makes a seed reproducible.
    torch.set_num_threads(1)
    try:
        return _train(config, seed, TABLE2 if groups is None else groups, log)
    finally:
        torch.set_num_threads(threads)


def _train(
    config: DQNConfig, seed: int, groups: dict[int, SyncGroup], log: Callable[[str], None] | None
) -> TrainingResult:
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    learner = DQNLearner(
        L3QNetwork(), learning_rate=config.learning_rate, max_grad_norm=config.max_grad_norm, double_q=config.double_q
    )
    online = learner.online
    buffer = ReplayBuffer(config.buffer_size, OBS_SIZE)
    envs = _grouped_envs(list(groups.values()), config.copies, config.episode_seconds)
    ticks_per_round = max(env.n_steps for env in envs)
    total_ticks = config.episodes * ticks_per_round
    decay_ticks = max(1, round(config.eps_decay_fraction * total_ticks))
    n_actions = len(ACTIONS)

    # Ticks within a round after which the greedy policy is evaluated, the last one ending the round.
    checks = config.checks_per_episode
    check_ticks = {round(i * ticks_per_round / checks) for i in range(1, checks + 1)}
    history: list[dict] = []
    best_score, best_state, best_check = -np.inf, copy.deepcopy(online.state_dict()), 0
    obs = np.concatenate([env.reset() for env in envs])
    gradient_steps, losses, started, started_cpu = 0, [], time.perf_counter(), time.process_time()
    for tick in range(1, total_ticks + 1):
        epsilon = config.eps_end + (config.eps_start - config.eps_end) * max(0.0, 1.0 - tick / decay_ticks)
        with torch.no_grad():
            actions = online(torch.from_numpy(obs.astype(np.float32))).argmax(dim=1).numpy()
        explore = rng.random(len(actions)) < epsilon
        actions = np.where(explore, rng.integers(n_actions, size=len(actions)), actions)

        next_obs, rewards, offset = [], [], 0
        for env in envs:
            r_now = env.r
            env_next_obs, r_next, done = env.step(actions[offset : offset + env.batch_size])
            offset += env.batch_size
            next_obs.append(env_next_obs)
            rewards.append(config.reward_scale * (r_next - r_now))
            if done:
                env.reset()
        # Time limits truncate, never terminate: every transition bootstraps.
        buffer.add(obs, actions, np.concatenate(rewards), np.concatenate(next_obs), np.zeros(len(actions), dtype=bool))
        # After a reset the next decision starts from the fresh episode, not from next_obs.
        obs = np.concatenate([env.observation for env in envs])

        if buffer.size >= config.learning_starts and tick % config.train_every == 0:
            losses.append(learner.update(buffer.sample(rng, config.batch_size), config.gamma))
            gradient_steps += 1
            if gradient_steps % config.target_every == 0:
                learner.update_target()

        if (tick - 1) % ticks_per_round + 1 in check_ticks:
            change_pct = _evaluate_until_worse(
                DQNPolicy(copy.deepcopy(online)), groups, best_score, config.episode_seconds
            )
            score = _selection_score(change_pct)
            record = {
                "episode": tick / ticks_per_round,
                "epsilon": epsilon,
                "loss": float(np.mean(losses)) if losses else float("nan"),
                "change_pct": change_pct,
                "score": score,
            }
            if score > best_score:
                best_score, best_state, best_check = score, copy.deepcopy(online.state_dict()), len(history)
            history.append(record)
            if log is not None:
                changes = " ".join(f"g{g} {c:+.2f}%" for g, c in change_pct.items())
                log(
                    f"episode {record['episode']:.2f}/{config.episodes}  eps {epsilon:.3f}  loss {record['loss']:.4f}"
                    f"  {changes}  score {score:.3f}  ({time.perf_counter() - started:.0f} s, "
                    f"CPU {time.process_time() - started_cpu:.0f} s)"
                )
            losses = []

    online.load_state_dict(best_state)
    return TrainingResult(network=online, history=history, best=best_check)


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m cogblocks.training.sync_dqn",
        description="Train the DQN L3 motion computer (PoP of Social Connectedness) in the closed loop with L2.",
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of weights, exploration and replay (default 0)")
    parser.add_argument("--out", type=Path, required=True, help="where to save the selected network's state_dict")
    parser.add_argument(
        "--episodes",
        type=int,
        default=None,
        help=f"training rounds, one 300 s episode per copy of groups 2 and 3 "
        f"(default {DQNConfig.episodes}; {QUICK_CONFIG.episodes} with --quick)",
    )
    parser.add_argument(
        "--randomised",
        action="store_true",
        help="train on randomised groups of the train split and select on the validation split "
        "(cogblocks.training.sync_dqn_random; --episodes does not apply)",
    )
    parser.add_argument(
        "--quick",
        action="store_true",
        help="smoke test: 20 s episodes, fewer copies, rounds and checks (about a minute)",
    )
    return parser


def main(argv: Sequence[str] | None = None) -> None:
    """Command-line entry point: train, report the selected network's evaluation and save its ``state_dict``."""
    args = _parser().parse_args(argv)
    if args.randomised:
        _main_randomised(args)
        return
    config = QUICK_CONFIG if args.quick else DQNConfig()
    if args.episodes is not None:
        config = dataclasses.replace(config, episodes=args.episodes)
    started = time.perf_counter()
    result = train(config, args.seed)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    torch.save(result.network.state_dict(), args.out)
    best = result.history[result.best]
    changes = ", ".join(f"group {g} {c:+.2f} %" for g, c in best["change_pct"].items())
    print(
        f"saved the network of episode {best['episode']:.2f} ({changes}) to {args.out.resolve()} "
        f"after {time.perf_counter() - started:.0f} s"
    )


def _main_randomised(args: argparse.Namespace) -> None:
    from cogblocks.training.sync_dqn_random import QUICK_RANDOMISED, RandomisedConfig, train_randomised

    if args.episodes is not None:
        raise SystemExit("--episodes does not apply to --randomised training")
    started = time.process_time()
    result = train_randomised(QUICK_RANDOMISED if args.quick else RandomisedConfig(), args.seed)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    torch.save(result.network.state_dict(), args.out)
    best = result.history[result.best]
    print(
        f"saved the network of tick {best['tick']} (validation: lowered {best['lowered']}, mean "
        f"{best['mean_change_pct']:+.3f} %, worst {best['worst_change_pct']:+.3f} %) to {args.out.resolve()} "
        f"after {time.process_time() - started:.0f} CPU s"
    )


if __name__ == "__main__":
    main()
