"""The RL corrector of the PoP of Amplification: reward, block, training environment, DQN."""

import numpy as np
import pytest
import torch

from cogblocks.amplification import (
    CorrectorNet,
    EncoderNet,
    L2Amplification,
    NoCorrection,
    RLCorrector,
    load_corrector,
    solution_table,
)
from cogblocks.amplification.corrector import ACTIONS, reward_constants, step_reward
from cogblocks.blocks import Playback
from cogblocks.data.reach import generate_reach_library
from cogblocks.sim import Diagram, Simulator
from cogblocks.training.amplification_env import AmplificationEnv, record_episodes
from cogblocks.training.corrector import CorrectorConfig, evaluate, train

torch.set_num_threads(1)  # tiny networks: threads only add contention on a shared machine


def test_reward_constants_of_the_paper():
    r_in, r_exit = reward_constants(100)
    assert r_in == pytest.approx(273.2, abs=0.05)
    assert r_exit == pytest.approx(-101953, abs=1)


def test_step_reward_prize_and_punishment():
    p_h = np.zeros((3, 3))
    p_a = np.array([[5.0, 0, 0], [30.0, 0, 0], [30.0, 0, 0]])
    v_h = np.zeros((3, 3))
    alpha = np.array([[1.0, 1, 0], [0, 0, 0], [0, 0, 0]])
    was_inside = np.array([False, True, False])
    reward, inside = step_reward(p_h, p_a, v_h, alpha, was_inside, 100.0, -1000.0)
    np.testing.assert_array_equal(inside, [True, False, False])
    np.testing.assert_allclose(reward, [-0.05 - 20 + 100, -0.3 - 1000, -0.3])
    moving = step_reward(p_h, p_a, np.ones((3, 3)), alpha, was_inside, 100.0, -1000.0)[1]
    assert not moving.any()  # the goal set needs the human at rest


def constant_policy(action):
    net = CorrectorNet()
    with torch.no_grad():
        for p in net.parameters():
            p.zero_()
        net.layers[-1].bias[action] = 1.0
    return net.eval()


@pytest.fixture(scope="module")
def small_setup():
    library = generate_reach_library(1, n_subjects=2, n_fear=6, n_no_fear=7)
    torch.manual_seed(0)
    net = EncoderNet(hidden=8).double().eval()
    with torch.no_grad():
        net.scale.fill_(200.0)
    return library, solution_table(net, library, cache_dir=None)


def closed_loop(library, table, human, corrector, n_steps=200):
    candidates = np.ones(len(library), dtype=bool)
    candidates[human] = False
    d = Diagram()
    d.add("v", Playback(library.velocity[human], unit="mm/s", at_end="zero"))
    d.add("p", Playback(library.position[human], unit="mm", at_end="hold"))
    d.add("l2", L2Amplification(library, table, corrector=corrector, candidates=candidates))
    d.connect("v.y", "l2.v_h")
    d.connect("p.y", "l2.p_h")
    probes = {"p_a": "l2.p_a", "v_a": "l2.v_a", "v_u": "l2.v_u", "alpha": "l2.alpha", "p_h": "p.y"}
    return Simulator(d, probes=probes).run(n_steps=n_steps)


def test_corrector_schedule_and_correction(small_setup):
    library, table = small_setup
    human = int(np.flatnonzero(~library.fear)[0])
    trace = closed_loop(library, table, human, RLCorrector(constant_policy(7)))
    alpha = trace["alpha"]
    assert (alpha[:10] == 0).all() and (alpha[10:] == 1).all()
    gap = trace["p_h"][:-1] - trace["p_a"][:-1]
    np.testing.assert_allclose(trace["v_u"][1:], 6.0 * alpha[1:] * gap)
    assert np.linalg.norm(trace["p_a"][-1] - trace["p_h"][-1]) < 1.0  # always correcting closes the gap


def test_no_correction_has_the_ports_of_the_rl_corrector():
    rl, none = RLCorrector(constant_policy(0)), NoCorrection()
    assert set(rl.inputs) == set(none.inputs) and set(rl.outputs) == set(none.outputs)
    with pytest.raises(ValueError, match="gain"):
        RLCorrector(constant_policy(0), gain=0.0)


def test_environment_replays_the_diagram(small_setup):
    library, table = small_setup
    humans = np.flatnonzero(~library.fear)[:3]
    episodes = record_episodes(library, table, humans)
    env = AmplificationEnv(episodes)
    state = env.reset(np.arange(len(humans)))
    actions = np.array([3, 7, 5])
    p_a = []
    done = np.zeros(len(humans), dtype=bool)
    while not done.all():
        state, _, done = env.step(actions)
        p_a.append(env.p_a.copy())
    assert env.t == 199
    for row, human in enumerate(humans):
        trace = closed_loop(library, table, int(human), RLCorrector(constant_policy(int(actions[row]))))
        np.testing.assert_allclose(env.p_a[row], trace["p_a"][-1], atol=1e-9)
        np.testing.assert_allclose(p_a[0][row], trace["p_a"][19], atol=1e-9)
    assert ACTIONS.shape == (8, 3)


def test_dqn_training_is_deterministic(small_setup):
    library, table = small_setup
    episodes = record_episodes(library, table, np.flatnonzero(~library.fear)[:2])
    config = CorrectorConfig(episodes=3, batch_size=8, learning_starts=8, eval_every=2, updates_per_decision=1)
    a = train(config, 5, episodes, log=None)
    b = train(config, 5, episodes, log=None)
    for (name, x), (_, y) in zip(a.network.state_dict().items(), b.network.state_dict().items(), strict=True):
        assert torch.equal(x, y), name
    assert [r["episode"] for r in a.history] == [2, 3]
    result = evaluate(a.network, episodes)
    assert 0.0 <= result["terminal_ok"] <= 1.0


def test_shipped_corrector_loads():
    net = load_corrector()
    assert net.checkpoint["config"]["episodes"] > 0
    q = net(torch.zeros(4, 13))
    assert q.shape == (4, 8)
