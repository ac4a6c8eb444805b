"""The DQN trained on randomised groups: its features, reward, data splits, selection and reproducibility."""

from __future__ import annotations

import cmath
import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
import torch

import cogblocks.training.sync_dqn_random as randomised
from cogblocks.data.groups import TABLE2, random_groups
from cogblocks.diagrams.sync import pop_sync
from cogblocks.diagrams.sync_motions import _l3_motion
from cogblocks.sim import Simulator
from cogblocks.sync.dqn_policy import FEATURE_SIZE, OBS_SIZE, DQNPolicy, L3QNetwork, group_features
from cogblocks.sync.motion import HOLD_ACTION, L3Context
from cogblocks.training.sync_dqn_random import RandomisedConfig, selection_key, train_randomised, validation_changes
from cogblocks.training.sync_env import SyncEnv, evaluate, order_parameter_without_l2

torch.set_num_threads(1)  # tiny networks: threads only add contention on a shared machine

TINY = RandomisedConfig(
    ticks=240,
    slots=2,
    copies=2,
    window=(0.5, 1.0),
    train_pool=6,
    validation_groups=2,
    validation_seconds=0.5,
    checks=2,
    learning_starts=64,
    batch_size=16,
    buffer_size=2_000,
    target_every=20,
)


def _features_by_hand(theta_l3, theta, a, lam, omega_prev, omega_init):
    others = [cmath.exp(1j * t) for j, t in enumerate(theta) if j != a]
    mean = sum(others) / len(others)
    psi = cmath.phase(mean)
    row = []
    for angle in (theta_l3 - psi, theta[a] - psi, theta_l3 - theta[a]):
        row += [math.sin(angle), math.cos(angle)]
    return row + [abs(mean), lam, omega_prev - omega_init, 1 / len(theta)]


def test_group_features_against_an_independent_computation() -> None:
    rng = np.random.default_rng(3)
    theta, theta_l3 = rng.uniform(0, 2 * np.pi, (4, 6)), rng.uniform(0, 2 * np.pi, 4)
    lam, omega_prev = rng.uniform(0.4, 1.6, 4), rng.uniform(-5, 5, 4)
    batched = group_features(theta_l3, theta, 2, lam, omega_prev, 3.5)
    assert batched.shape == (4, FEATURE_SIZE)
    for b in range(4):
        expected = _features_by_hand(theta_l3[b], theta[b], 2, lam[b], omega_prev[b], 3.5)
        np.testing.assert_allclose(batched[b], expected, atol=1e-12)
    # Everyone together, reference on them: the others are coherent and the angles all vanish.
    np.testing.assert_allclose(group_features(1.0, np.ones(3), 0, 0.5, 2.0, 2.0), [0, 1, 0, 1, 0, 1, 1, 0.5, 0, 1 / 3])


def test_network_sizes_and_loading_either_observation(tmp_path: Path) -> None:
    assert L3QNetwork(FEATURE_SIZE)(torch.zeros(2, FEATURE_SIZE)).shape == (2, 11)
    with pytest.raises(ValueError, match="obs_size must be 3 or 10"):
        L3QNetwork(4)
    for size in (OBS_SIZE, FEATURE_SIZE):
        torch.save(L3QNetwork(size).state_dict(), tmp_path / f"{size}.pt")
        assert DQNPolicy.from_file(tmp_path / f"{size}.pt").network.obs_size == size


def test_feature_policy_needs_the_assisted_index() -> None:
    policy = DQNPolicy(L3QNetwork(FEATURE_SIZE))
    policy.reset(3.0)
    context = SyncEnv.from_group(TABLE2[1]).context()
    assert context.assisted == TABLE2[1].assisted
    policy.act(context)
    with pytest.raises(ValueError, match="assisted index"):
        policy.act(dataclasses.replace(context, assisted=None))
    assert isinstance(context, L3Context)


def _short(groups, seconds):
    return [dataclasses.replace(g, duration=min(g.duration, seconds)) for g in groups]


def test_batched_validation_equals_the_policy_in_the_env_and_in_the_diagram() -> None:
    torch.manual_seed(4)
    network = L3QNetwork(FEATURE_SIZE)
    groups = _short(random_groups(3, "validation"), 2.0)
    batched = validation_changes(network, groups)
    one_by_one = [evaluate(DQNPolicy(network), g)["change_pct"] for g in groups]
    np.testing.assert_allclose(batched, one_by_one, rtol=0, atol=1e-12)
    # The diagram's MotionComputer gives the policy the same features (it passes the assisted index).
    group = groups[0]
    r = Simulator(pop_sync(group, motion=_l3_motion(group, DQNPolicy(network)), blender="deliverable")).run(
        n_steps=201
    )["r"]
    r_without = order_parameter_without_l2(group)
    assert 100 * (float(r.mean()) - r_without) / r_without == pytest.approx(batched[0], abs=1e-7)


def test_reward_gain_is_r_with_minus_the_no_l2_run() -> None:
    group = _short(random_groups(1, "train"), 1.0)[0]
    slot = randomised._Slot(group, 2)
    without = SyncEnv.from_group(group, l2=False)
    while True:
        np.testing.assert_allclose(slot.r_without[without.k], without.r[0], rtol=0, atol=1e-15)
        np.testing.assert_allclose(slot.gain(), slot.env.r - without.r[0], rtol=0, atol=1e-15)
        if without.done:
            break
        without.step(np.array([HOLD_ACTION]))
        slot.env.step(np.array([0, 10]))
    assert slot.r_without.mean() == pytest.approx(order_parameter_without_l2(group), abs=1e-12)


def test_selection_key_prefers_fewer_lowered_then_higher_mean() -> None:
    assert selection_key([1.0, -0.5, 2.5]) == (1, -1.0)
    assert selection_key([0.0, 0.5]) < selection_key([5.0, -0.01]) < selection_key([1.0, -0.5, -0.5])
    assert selection_key([0.2, 0.4]) < selection_key([0.1, 0.2])


def _weights(seed: int) -> list[torch.Tensor]:
    with torch.random.fork_rng():
        return list(train_randomised(TINY, seed, log=None).network.state_dict().values())


def test_randomised_training_is_reproducible_from_the_seed() -> None:
    first, again, other = _weights(1), _weights(1), _weights(2)
    assert all(torch.equal(a, b) for a, b in zip(first, again, strict=True))
    assert not all(torch.equal(a, b) for a, b in zip(first, other, strict=True))


def test_training_draws_train_groups_and_selects_on_validation_groups(monkeypatch: pytest.MonkeyPatch) -> None:
    splits, evaluated = [], []
    real_groups, real_changes = randomised.random_groups, randomised.validation_changes

    def recording_groups(n, split="train", seed=0):
        splits.append(split)
        return real_groups(n, split, seed)

    def recording_changes(network, groups):
        evaluated.append(list(groups))
        return real_changes(network, groups)

    monkeypatch.setattr(randomised, "random_groups", recording_groups)
    monkeypatch.setattr(randomised, "validation_changes", recording_changes)
    with torch.random.fork_rng():
        result = train_randomised(TINY, 0, log=None)

    assert "test" not in splits
    pool = {dataclasses.replace(g, duration=0.0) for g in real_groups(TINY.train_pool, "train")}
    held_out = real_groups(50, "validation") + real_groups(50, "test")
    assert len(result.groups_drawn) >= TINY.slots
    for group in result.groups_drawn:
        assert dataclasses.replace(group, duration=0.0) in pool
        assert group.duration <= TINY.window[1]
        assert all(group.omega != other.omega for other in held_out)
    expected = _short(real_groups(TINY.validation_groups, "validation"), TINY.validation_seconds)
    assert evaluated == [expected] * TINY.checks
    assert len(result.history) == TINY.checks
    keys = [(h["lowered"], -h["mean_change_pct"]) for h in result.history]
    assert keys[result.best] == min(keys)
    assert keys.index(min(keys)) == result.best
    changes = validation_changes(result.network, expected)
    assert selection_key(changes) == keys[result.best]
