"""The stable-baselines3 DQN on the sync environment: a tiny run, evaluated like the project's policies."""

import json

import numpy as np
import pytest

pytest.importorskip("stable_baselines3", reason="the rl extra (stable-baselines3) is not installed")

import torch  # noqa: E402
from stable_baselines3 import DQN  # noqa: E402

from cogblocks.data.groups import TABLE2  # noqa: E402
from cogblocks.sync import DQNPolicy  # noqa: E402
from cogblocks.training.sb3_sync import SB3Policy, main  # noqa: E402
from cogblocks.training.sync_env import SyncEnv, evaluate  # noqa: E402


def test_tiny_training_and_side_by_side_evaluation(tmp_path, capsys):
    out = tmp_path / "sb3.zip"
    main(["--timesteps", "300", "--episode-seconds", "1", "--groups", "1", "--seed", "3", "--out", str(out), "--json"])
    rows = {row["policy"]: row for row in map(json.loads, capsys.readouterr().out.splitlines())}
    assert set(rows) == {"sb3_dqn", "dqn", "lookahead"}
    assert rows["dqn"] == {"group": "1", "policy": "dqn", **evaluate(DQNPolicy.default(), TABLE2[1])}
    assert rows["lookahead"]["r_without"] == rows["dqn"]["r_without"]  # the same group for every policy
    model = DQN.load(out, device="cpu")
    assert rows["sb3_dqn"]["r_with"] == evaluate(SB3Policy(model), TABLE2[1])["r_with"]
    # the adapter is the greedy action of the model's Q-network
    env = SyncEnv.from_group(TABLE2[1])
    env.reset()
    policy = SB3Policy(model)
    for _ in range(20):
        context = env.context()
        with torch.no_grad():
            q = model.q_net(torch.as_tensor(context.obs[None], dtype=torch.float32))
        assert policy.act(context) == int(q.argmax())
        env.step(np.array([policy.act(context)]))
