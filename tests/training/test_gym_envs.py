"""The Gymnasium environments: the env checker, and the same numbers as the project's own environments."""

import subprocess
import sys

import numpy as np
import pytest

gymnasium = pytest.importorskip("gymnasium", reason="the rl extra (gymnasium) is not installed")

from gymnasium.utils.env_checker import check_env  # noqa: E402

from cogblocks.amplification import load_encoder, solution_table  # noqa: E402
from cogblocks.data.groups import TABLE2  # noqa: E402
from cogblocks.data.reach import generate_reach_library  # noqa: E402
from cogblocks.training.amplification_env import AmplificationEnv, record_episodes  # noqa: E402
from cogblocks.training.gym_envs import (  # noqa: E402
    CORRECTOR_ID,
    SYNC_ID,
    CorrectorEnv,
    SyncL3Env,
    SyncL3VectorEnv,
)
from cogblocks.training.sync_env import SyncEnv  # noqa: E402


@pytest.fixture(scope="module")
def episodes():
    library = generate_reach_library(0, n_subjects=2, n_fear=4, n_no_fear=4)
    table = solution_table(load_encoder(), library, 1)
    return record_episodes(library, table, np.flatnonzero(~library.fear)[:3])


def test_sync_env_passes_the_checker_and_matches_sync_env():
    env = gymnasium.make(SYNC_ID, episode_seconds=0.5)
    check_env(env.unwrapped, skip_render_check=True)
    obs, info = env.reset(seed=0, options={"group": 0})
    assert info["group"] == TABLE2[1].name
    reference = SyncEnv.from_group(TABLE2[1])
    np.testing.assert_allclose(obs, reference.reset()[0].astype(np.float32))
    actions = np.random.default_rng(1).integers(11, size=50)
    for k, action in enumerate(actions):
        r_before = reference.r[0]
        expected, r, done = reference.step(np.array([action]))
        obs, reward, terminated, truncated, info = env.step(action)
        np.testing.assert_array_equal(obs, expected[0].astype(np.float32))
        assert reward == 100.0 * (r[0] - r_before) and info["r"] == r[0]
        assert not terminated and truncated == (k == 49)
    assert info["mean_order_parameter"] == reference.mean_order_parameter[0]


def test_sync_env_draws_groups_from_its_seed():
    env = SyncL3Env(episode_seconds=0.1)
    first = [env.reset(seed=s)[1]["group"] for s in range(8)]
    again = [env.reset(seed=s)[1]["group"] for s in range(8)]
    assert first == again and len(set(first)) > 1


def test_vector_env_is_the_batched_sync_env_with_next_step_autoreset():
    venv = gymnasium.make_vec(SYNC_ID, num_envs=3, vectorization_mode="vector_entry_point", episode_seconds=0.05)
    assert isinstance(venv.unwrapped, SyncL3VectorEnv)
    singles = [SyncL3Env([TABLE2[3]], episode_seconds=0.05) for _ in range(3)]
    obs, _ = venv.reset(seed=0)
    np.testing.assert_array_equal(obs, np.stack([e.reset(seed=0)[0] for e in singles]))
    rng = np.random.default_rng(2)
    for k in range(5):
        actions = rng.integers(11, size=3)
        obs, reward, terminated, truncated, info = venv.step(actions)
        outs = [e.step(a) for e, a in zip(singles, actions, strict=True)]
        np.testing.assert_array_equal(obs, np.stack([o[0] for o in outs]))
        np.testing.assert_allclose(reward, [o[1] for o in outs], rtol=1e-12, atol=1e-15)
        assert not terminated.any() and (truncated == (k == 4)).all()
    assert info["_mean_order_parameter"].all()
    np.testing.assert_array_equal(info["mean_order_parameter"], [o[4]["mean_order_parameter"] for o in outs])
    obs, reward, _, truncated, _ = venv.step(np.zeros(3, dtype=np.int64))  # the autoreset step
    np.testing.assert_array_equal(obs, np.stack([e.reset()[0] for e in singles]))
    assert (reward == 0).all() and not truncated.any()
    with pytest.raises(ValueError, match="num_envs must be an integer >= 1"):
        SyncL3VectorEnv(0)


def test_corrector_env_passes_the_checker_and_matches_amplification_env(episodes):
    env = gymnasium.make(CORRECTOR_ID, episodes=episodes)
    check_env(env.unwrapped, skip_render_check=True)
    reference = AmplificationEnv(episodes)
    obs, info = env.reset(seed=0, options={"movement": 2})
    np.testing.assert_array_equal(obs, reference.reset(np.array([2]))[0])
    rng = np.random.default_rng(3)
    ended = False
    while not ended:
        action = int(rng.integers(8))
        state, reward, done = reference.step(np.array([action]))
        obs, r, terminated, truncated, info = env.step(action)
        np.testing.assert_array_equal(obs, state[0])
        assert r == reward[0] and info["distance_mm"] == reference.final_distance()[0]
        ended = terminated or truncated
        assert ended == done[0]
    assert isinstance(CorrectorEnv(episodes).reset(seed=1)[1]["movement"], int)


def test_importing_cogblocks_does_not_import_gymnasium():
    code = "import sys, cogblocks, cogblocks.sim, cogblocks.cli; print('gymnasium' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
