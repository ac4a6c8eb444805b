"""L3 policies: network, greedy DQN policy and its training, look-ahead policy, and the Table 3 targets."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import torch

from cogblocks.data.groups import TABLE2, TABLE3_CHANGE_PCT
from cogblocks.sync import DQNPolicy, LookaheadPolicy
from cogblocks.sync.dqn_policy import L3QNetwork
from cogblocks.sync.motion import ACTIONS, HOLD_ACTION
from cogblocks.training.sync_dqn import DQNConfig, train
from cogblocks.training.sync_env import SyncEnv, evaluate

torch.set_num_threads(1)  # tiny networks: threads only add contention on a shared machine

TINY_CONFIG = DQNConfig(
    episodes=2,
    copies=1,
    episode_seconds=1.0,
    learning_starts=64,
    batch_size=32,
    buffer_size=2_000,
    train_every=1,
    target_every=20,
)


def test_action_set() -> None:
    np.testing.assert_array_equal(ACTIONS, [-0.5, -0.4, -0.3, -0.2, -0.1, 0.0, 0.1, 0.2, 0.3, 0.4, 0.5])
    assert ACTIONS[HOLD_ACTION] == 0.0


def test_network_shape() -> None:
    network = L3QNetwork()
    shapes = [tuple(p.shape) for p in network.parameters()]
    assert shapes == [(128, 3), (128,), (64, 128), (64,), (11, 64), (11,)]
    assert network(torch.zeros(5, 3)).shape == (5, 11)


def test_dqn_policy_round_trip(tmp_path: Path) -> None:
    torch.manual_seed(0)
    network = L3QNetwork()
    torch.save(network.state_dict(), tmp_path / "net.pt")
    env = SyncEnv.from_group(TABLE2[1])
    context = env.context()
    expected = int(network(torch.as_tensor(context.obs, dtype=torch.float32)).argmax())
    assert DQNPolicy.from_file(tmp_path / "net.pt").act(context) == expected


def _weights(seed: int) -> list[torch.Tensor]:
    with torch.random.fork_rng():
        result = train(TINY_CONFIG, seed, log=None)
    assert len(result.history) == TINY_CONFIG.episodes * TINY_CONFIG.checks_per_episode
    assert np.isfinite(result.history[-1]["loss"])
    assert result.history[result.best]["score"] == max(entry["score"] for entry in result.history)
    return list(result.network.state_dict().values())


def test_training_is_reproducible_from_the_seed() -> None:
    first, again, other = _weights(1), _weights(1), _weights(2)
    assert all(torch.equal(a, b) for a, b in zip(first, again, strict=True))
    assert not all(torch.equal(a, b) for a, b in zip(first, other, strict=True))


def test_lookahead_predicts_the_closed_loop() -> None:
    group, warmup, horizon = TABLE2[3], 150, 10
    policy = LookaheadPolicy.for_group(group, horizon=horizon)
    env = SyncEnv.from_group(group, len(ACTIONS))
    for _ in range(warmup):
        env.step(np.full(len(ACTIONS), HOLD_ACTION))
    predicted = policy.predicted_order_parameter(env.context())
    # Repeating each action in the real loop must give exactly the predicted future order parameter.
    rewards = [env.step(np.arange(len(ACTIONS)))[1] for _ in range(horizon)]
    np.testing.assert_allclose(predicted, np.mean(rewards, axis=0), rtol=0, atol=1e-12)


def _assert_beats_table3(result: dict[str, float], group_number: int) -> None:
    assert result["change_pct"] >= TABLE3_CHANGE_PCT[group_number]
    assert result["alteration_max"] <= np.pi / 2


@pytest.mark.parametrize("weights", ["sync_dqn.pt", "sync_dqn_table2.pt"])
def test_shipped_dqn_meets_target_on_group1(weights: str) -> None:
    _assert_beats_table3(evaluate(DQNPolicy.default(weights), TABLE2[1]), 1)


# The network trained and selected on Table 2's groups beats Table 3 on the 300 s groups; the shipped one,
# trained on randomised groups and selected on the validation split, is only required not to lower r there.
@pytest.mark.parametrize("group_number", [2, 3])
def test_table2_dqn_meets_target_on_300s_groups(group_number: int) -> None:
    _assert_beats_table3(evaluate(DQNPolicy.default("sync_dqn_table2.pt"), TABLE2[group_number]), group_number)


@pytest.mark.parametrize("group_number", [2, 3])
def test_shipped_dqn_raises_r_on_300s_groups(group_number: int) -> None:
    result = evaluate(DQNPolicy.default(), TABLE2[group_number])
    assert result["r_with"] > result["r_without"]
    assert result["alteration_max"] <= np.pi / 2


def test_lookahead_meets_target_on_group1() -> None:
    _assert_beats_table3(evaluate(LookaheadPolicy.for_group(TABLE2[1]), TABLE2[1]), 1)


@pytest.mark.slow
@pytest.mark.parametrize("group_number", [2, 3])
def test_lookahead_meets_target_on_300s_groups(group_number: int) -> None:
    _assert_beats_table3(evaluate(LookaheadPolicy.for_group(TABLE2[group_number]), TABLE2[group_number]), group_number)


def test_lookahead_rejects_batched_models() -> None:
    model = dataclasses.replace(LookaheadPolicy.for_group(TABLE2[1]).model, omega=np.zeros((2, 5)))
    with pytest.raises(ValueError):
        LookaheadPolicy(model)


def test_training_command_help(capsys: pytest.CaptureFixture[str]) -> None:
    from cogblocks.training.sync_dqn import main

    with pytest.raises(SystemExit) as exit_info:
        main(["--help"])
    assert exit_info.value.code == 0
    assert "--episodes" in capsys.readouterr().out
