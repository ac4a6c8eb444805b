"""A stable-baselines3 DQN on ``cogblocks/SyncL3-v0``, evaluated beside the project's own L3 policies (extra ``rl``).

Usage::

    python -m cogblocks.training.sb3_sync --timesteps 200000 --seed 0 --out sb3.zip [--groups 1,2,3] [--random N]

It trains ``stable_baselines3.DQN`` (an MLP of 128 and 64 ReLU units, as
:class:`~cogblocks.sync.dqn_policy.L3QNetwork`; γ = 0.99, the reward of the project's trainer)
on :class:`~cogblocks.training.gym_envs.SyncL3Env` over Table 2's groups, then evaluates its greedy
policy with :func:`~cogblocks.training.sync_env.evaluate` on the same groups as the shipped
:class:`~cogblocks.sync.DQNPolicy` and the :class:`LookaheadPolicy` (and on
``--random N`` held-out groups when ``cogblocks.data.groups.random_groups`` exists). The project's
trainer (:mod:`cogblocks.training.sync_dqn`) stays the reproducible reference: SB3 is a second opinion.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from cogblocks.data import groups as group_data
from cogblocks.data.groups import TABLE2, SyncGroup
from cogblocks.sync import DQNPolicy, L3Context, LookaheadPolicy
from cogblocks.training.sync_env import evaluate

__all__ = ["SB3Policy", "compare", "main", "train_sb3"]


class SB3Policy:
    """The greedy action of a stable-baselines3 model, as an :class:`~cogblocks.sync.L3Policy`."""

    def __init__(self, model: Any) -> None:
        self.model = model

    def reset(self, omega_init: float) -> None:
        """The policy is memoryless: nothing to reset."""

    def act(self, context: L3Context) -> int:
        """The model's deterministic action for ``context.obs``."""
        action, _ = self.model.predict(np.asarray(context.obs, dtype=np.float32), deterministic=True)
        return int(action)


def train_sb3(timesteps: int, seed: int, *, episode_seconds: float | None = None) -> Any:
    """Train a stable-baselines3 DQN on :class:`SyncL3Env` for ``timesteps`` steps; returns the model."""
    import torch
    from stable_baselines3 import DQN

    from cogblocks.training.gym_envs import SyncL3Env

    torch.set_num_threads(1)
    env = SyncL3Env(episode_seconds=episode_seconds)
    model = DQN(
        "MlpPolicy",
        env,
        learning_rate=1e-3,
        buffer_size=100_000,
        learning_starts=min(1000, timesteps // 2),
        batch_size=64,
        gamma=0.99,
        train_freq=4,
        target_update_interval=1000,
        exploration_fraction=0.3,
        exploration_final_eps=0.02,
        policy_kwargs={"net_arch": [128, 64]},
        seed=seed,
        device="cpu",
    )
    model.learn(total_timesteps=timesteps)
    return model


def compare(model: Any, groups: dict[str, SyncGroup]) -> list[dict[str, Any]]:
    """``change_pct`` and ``r_with`` of the SB3 policy, the shipped DQN and the lookahead policy on each group."""
    rows = []
    for label, group in groups.items():
        policies = {
            "sb3_dqn": SB3Policy(model),
            "dqn": DQNPolicy.default(),
            "lookahead": LookaheadPolicy.for_group(group),
        }
        for name, policy in policies.items():
            result = evaluate(policy, group)
            rows.append({"group": label, "policy": name, **result})
    return rows


def _groups(numbers: Sequence[int], random: int | None, seed: int) -> dict[str, SyncGroup]:
    unknown = [n for n in numbers if n not in TABLE2]
    if unknown:
        raise ValueError(f"Table 2 has groups {sorted(TABLE2)}, got {unknown}")
    groups = {str(n): TABLE2[n] for n in numbers}
    if random:
        make = getattr(group_data, "random_groups", None)
        if make is None:
            raise ValueError("random groups need cogblocks.data.groups.random_groups")
        groups.update({f"test{i}": g for i, g in enumerate(make(random, split="test", seed=seed))})
    return groups


def main(argv: Sequence[str] | None = None) -> None:
    """Command-line entry point: train, save, evaluate, print the comparison."""
    parser = argparse.ArgumentParser(
        prog="python -m cogblocks.training.sb3_sync",
        description="Train a stable-baselines3 DQN on cogblocks/SyncL3-v0 and compare it with the project's policies.",
    )
    parser.add_argument("--timesteps", type=int, default=200_000, help="training steps (default 200000)")
    parser.add_argument("--seed", type=int, default=0, help="seed of SB3 and of the group draws (default 0)")
    parser.add_argument("--episode-seconds", type=float, help="cap on training episodes (smoke tests)")
    parser.add_argument(
        "--groups", default="1,2,3", help="Table 2's groups to evaluate on (default 1,2,3; training uses all three)"
    )
    parser.add_argument("--random", type=int, metavar="N", help="also evaluate on N held-out random groups")
    parser.add_argument("--out", type=Path, help="save the SB3 model (.zip)")
    parser.add_argument("--json", action="store_true", help="print the comparison as JSON lines")
    args = parser.parse_args(argv)

    groups = _groups(
        [int(g) for g in args.groups.split(",") if g], args.random, args.seed
    )  # fails early if random groups are asked for and missing
    started = time.perf_counter()
    model = train_sb3(args.timesteps, args.seed, episode_seconds=args.episode_seconds)
    trained = time.perf_counter() - started
    if args.out:
        model.save(args.out)
    rows = compare(model, groups)
    if args.json:
        for row in rows:
            print(json.dumps(row))
        return
    print(f"SB3 DQN: {args.timesteps} steps in {trained:.0f} s; change of the mean order parameter with L2:")
    for row in rows:
        print(f"  group {row['group']:>6}  {row['policy']:>9}: r {row['r_with']:.4f} ({row['change_pct']:+.2f} %)")


if __name__ == "__main__":
    main()
