"""The shared DQN machinery: replay buffer bookkeeping and the TD update against hand computation."""

import numpy as np
import torch
from torch import nn

from cogblocks.training.dqn import Batch, DQNLearner, ReplayBuffer


def test_replay_buffer_wraps_and_samples_what_was_stored():
    buffer = ReplayBuffer(capacity=5, obs_size=2)
    for start in (0, 3, 6):  # 9 transitions into 5 rows: the last 5 remain
        idx = np.arange(start, start + 3)
        buffer.add(np.c_[idx, idx], idx, idx * 10.0, np.c_[idx + 1, idx + 1], idx % 2 == 0)
    assert buffer.size == 5
    assert sorted(buffer.actions.tolist()) == [4, 5, 6, 7, 8]
    batch = buffer.sample(np.random.default_rng(0), 64)
    a = batch.actions.numpy()
    assert set(a) <= {4, 5, 6, 7, 8}
    np.testing.assert_array_equal(batch.obs.numpy()[:, 0], a)
    np.testing.assert_array_equal(batch.rewards.numpy(), a * 10.0)
    np.testing.assert_array_equal(batch.next_obs.numpy()[:, 1], a + 1)
    np.testing.assert_array_equal(batch.terminal.numpy(), (a % 2 == 0).astype(np.float32))


def test_update_regresses_on_the_td_target_and_terminal_stops_bootstrapping():
    torch.manual_seed(0)
    learner = DQNLearner(nn.Linear(2, 3), learning_rate=0.0, max_grad_norm=1.0)
    obs = torch.tensor([[1.0, 0.0], [0.0, 1.0]])
    batch_args = dict(obs=obs, actions=torch.tensor([0, 2]), rewards=torch.tensor([1.0, -1.0]), next_obs=obs.flip(0))
    with torch.no_grad():
        q_next = learner.target(obs.flip(0)).max(dim=1).values
        q = learner.online(obs)[[0, 1], [0, 2]]
    for terminal in (torch.tensor([0.0, 0.0]), torch.tensor([1.0, 0.0])):
        target = batch_args["rewards"] + 0.9 * (1.0 - terminal) * q_next
        expected = nn.functional.smooth_l1_loss(q, target).item()
        loss = learner.update(Batch(**batch_args, terminal=terminal), 0.9)  # lr 0: the network stays put
        assert abs(loss - expected) < 1e-6


def test_update_lowers_the_loss_and_target_copy_syncs():
    torch.manual_seed(1)
    learner = DQNLearner(nn.Linear(2, 3), learning_rate=0.05, max_grad_norm=10.0)
    obs = torch.randn(16, 2)
    batch = Batch(obs, torch.randint(0, 3, (16,)), torch.randn(16), torch.randn(16, 2), torch.ones(16))
    losses = [learner.update(batch, 0.9) for _ in range(50)]
    assert losses[-1] < 0.5 * losses[0]
    assert not torch.equal(learner.online.weight, learner.target.weight)
    learner.update_target()
    assert torch.equal(learner.online.weight, learner.target.weight)
