"""The shielded L3 motion computer (ShieldedMotion): its prediction, its choice, what it emits and its bad data."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from cogblocks.data.groups import TABLE2, SyncGroup, random_groups
from cogblocks.diagrams.sync import MOTIONS, pop_sync
from cogblocks.sim import Diagram, Simulator
from cogblocks.sync import DQNPolicy, MeanPhaseMotion, MotionComputer, OscillatorMotion, ShieldedMotion
from cogblocks.sync.dqn_policy import NumpyDQNPolicy
from cogblocks.sync.model import SyncModel, order_parameter
from cogblocks.sync.motion import ACTIONS, OMEGA_L3_LIMIT, L3Context, l3_observation
from cogblocks.sync.pacing import NONE, margin_choice
from cogblocks.sync.shielded import FOLLOW


class SteerPolicy:
    """A memoryless policy of the test's: speeds the oscillator up while it trails participant 0, else slows it."""

    def reset(self, omega_init: float) -> None:
        pass

    def act(self, context: L3Context) -> int:
        return 8 if math.sin(context.theta[0] - context.theta_l3) > 0.0 else 3


def _motion(policy, n: int, assisted: int, gain: float, adjacency) -> OscillatorMotion:
    return OscillatorMotion(policy, n=n, assisted=assisted, gain=gain, omega_init=2.0, adjacency=adjacency)


def test_the_prediction_is_the_closed_loop_of_the_policy_and_of_doing_nothing_on_the_model():
    """Both rows of a rollout against an independent closed loop: SyncModel's blender and group, tick by tick."""
    rng = np.random.default_rng(4)
    n, assisted, gain = 5, 2, 0.9
    a = rng.uniform(0.0, 1.5, (n, n)) * (rng.random((n, n)) < 0.7)  # weighted, directed
    np.fill_diagonal(a, 0.0)
    omega, theta, lam = rng.uniform(1.0, 4.0, n), rng.uniform(0, 2 * np.pi, n), 1.2
    shield = ShieldedMotion(_motion(SteerPolicy(), n, assisted, gain, a), adjacency=a)
    shield.motion.theta_l3, shield.motion.omega_prev = 0.4, 2.5
    job = shield.start_rollout(theta, lam, (omega, gain), k=0, dt=0.01, steps=250)
    for budget in (1, 7, 1000):  # any chunks
        shield.advance_rollout(job, budget)
    model = SyncModel(omega, gain, a, assisted)
    means = []
    for follow in (False, True):
        th, l3, w, la, total = theta.copy(), 0.4, 2.5, np.array(lam), 0.0
        for k in range(250):
            reference = l3 if follow else th[assisted]
            seen, _, la_next = model.blend(th, np.array(reference), la)
            total += float(order_parameter(seen))
            context = L3Context(k, l3_observation(l3, th[np.arange(n) != assisted], w), th, l3, float(la), w, assisted)
            w = min(max(w + ACTIONS[SteerPolicy().act(context)], -OMEGA_L3_LIMIT), OMEGA_L3_LIMIT)
            th, l3_next = model.advance(th, seen, np.array(l3), np.array(w))
            l3, la = float(l3_next), la_next
        means.append(total / 250)
    np.testing.assert_allclose(job.scores, means, rtol=0, atol=1e-10)
    assert abs(means[1] - means[0]) > 1e-3  # the policy does change the prediction


def test_the_backup_part_scores_following_then_doing_nothing_against_doing_nothing_throughout():
    """A rollout with a backup part against an independent loop: the policy part tick by tick as above, then both
    rows doing nothing on SyncModel with the backup step; the scores are time averages over both parts."""
    rng = np.random.default_rng(5)
    n, assisted, gain = 4, 1, 0.7
    a = rng.uniform(0.2, 1.0, (n, n))
    np.fill_diagonal(a, 0.0)
    omega, theta, lam = rng.uniform(1.0, 4.0, n), rng.uniform(0, 2 * np.pi, n), 1.1
    steps, backup_steps, h = 60, 40, 0.05
    shield = ShieldedMotion(_motion(SteerPolicy(), n, assisted, gain, a), adjacency=a, backup=2.0)
    shield.motion.theta_l3, shield.motion.omega_prev = 0.4, 2.5
    job = shield.start_rollout(
        theta, lam, (omega, gain), k=0, dt=0.01, steps=steps, backup_steps=backup_steps, backup_step=h
    )
    for budget, backup_budget in ((7, 3), (100, 0), (0, 5), (0, 1000)):  # any chunks; the backup waits its turn
        shield.advance_rollout(job, budget, backup_budget)
    assert job.done and job.done_backup == backup_steps
    fine, coarse = SyncModel(omega, gain, a, assisted), SyncModel(omega, gain, a, assisted, dt=h)
    means = []
    for follow in (False, True):
        th, l3, w, la, total = theta.copy(), 0.4, 2.5, np.array(lam), 0.0
        for k in range(steps):
            seen, _, la_next = fine.blend(th, np.array(l3 if follow else th[assisted]), la)
            total += 0.01 * float(order_parameter(seen))
            context = L3Context(k, l3_observation(l3, th[np.arange(n) != assisted], w), th, l3, float(la), w, assisted)
            w = min(max(w + ACTIONS[SteerPolicy().act(context)], -OMEGA_L3_LIMIT), OMEGA_L3_LIMIT)
            th, l3_next = fine.advance(th, seen, np.array(l3), np.array(w))
            l3, la = float(l3_next), la_next
        for _ in range(backup_steps):
            seen, _, la = coarse.blend(th, np.array(th[assisted]), la)
            total += h * float(order_parameter(seen))
            th, _ = coarse.advance(th, seen, np.array(0.0), np.array(0.0))
        means.append(total / (steps * 0.01 + backup_steps * h))
    np.testing.assert_allclose(job.scores, means, rtol=0, atol=1e-10)


def test_with_a_backup_every_prediction_is_done_by_the_next_decision():
    """The policy part in the first half of the period, the backup part in the second: one decision a period."""
    group = TABLE2[1]
    theta, lam = _recorded(group, 6.0)
    shield = ShieldedMotion(MOTIONS["dqn_raw"](group), adjacency=group.graph, backup=9.0)
    _run(shield, theta, lam)
    # trusted from tick 100: the predictions started at 100, 200, 300, 400 are decided at 200, 300, 400, 500; the
    # one started at 500 is done by the last tick, 599, the next decision's tick being 600
    assert len(shield.predictions) == 4 and shield.job is not None and shield.job.done
    assert shield.job.backup_steps == round(9.0 / shield._stable_step(shield.model()[1]))


@pytest.mark.parametrize("ticks", [1, 2, 3, 7, 100])
@pytest.mark.parametrize("backup", [0.0, 0.3])
def test_a_prediction_is_done_within_its_period_for_any_period(ticks, backup):
    """A period's ticks' shares of the work finish a prediction, with or without a backup part."""
    n, gain = 4, 0.8
    shield = ShieldedMotion(_motion(SteerPolicy(), n, 1, gain, "ring"), decide_every=ticks * 0.01, backup=backup)
    rng = np.random.default_rng(ticks)
    model = (rng.uniform(1.0, 3.0, n), gain)
    shield.job = job = shield._rollout(rng.uniform(0, 2 * np.pi, n), 1.0, model, 0, 0.01)
    assert job.backup_steps == round(backup / shield._stable_step(gain))
    first = max(1, ticks // 2) if backup else ticks
    for _ in range(ticks):
        before = job.done_steps
        shield._advance_job()
        assert job.done_steps - before <= -(-job.steps // first)  # the work of a tick stays bounded
    assert job.done and np.isfinite(job.scores).all()


def test_margin_choice_never_leaves_doing_nothing_for_a_candidate_predicted_below_it_plus_the_margin():
    rng = np.random.default_rng(0)
    kinds = np.array([NONE, FOLLOW])
    for _ in range(2000):
        scores = rng.uniform(0.5, 0.52, 2)
        current, margin, switch = int(rng.integers(2)), float(rng.uniform(0, 0.01)), float(rng.uniform(0, 0.01))
        best = margin_choice(kinds, scores, current, margin, switch)
        assert best == 0 or scores[1] >= scores[0] + margin
        if scores[1] >= scores[0] + max(margin, switch):
            assert best == 1


def _recorded(group: SyncGroup, seconds: float) -> tuple[np.ndarray, np.ndarray]:
    """Phases and λ of a closed loop under the circular mean, to feed a motion computer open loop."""
    probes = {"theta": "group.theta", "lam": "l2.blender.lam"}
    trace = Simulator(pop_sync(group, motion="mean", blender="deliverable"), probes=probes).run(
        n_steps=round(seconds / 0.01)
    )
    return trace["theta"], trace["lam"]


def _run(block, theta: np.ndarray, lam: np.ndarray, record: list | None = None) -> np.ndarray:
    d = Diagram()
    m = d.add("m", block)
    d.expose_input("theta", m.theta)
    d.expose_input("lam", m.lam)
    if record is not None:
        update = block.update

        def recording(k: int) -> None:
            update(k)
            record.append(block.mode)  # the mode of tick k + 1's output

        block.update = recording
    return Simulator(d, probes={"ref": "m.theta_ref"}).run(n_steps=len(theta), inputs={"theta": theta, "lam": lam})[
        "ref"
    ]


def test_it_emits_the_policys_reference_or_the_participants_own_phase_as_its_prediction_says():
    """Open loop on recorded phases: every tick's θ_ref is the unshielded motion computer's (following) or θ_L0
    (doing nothing); it follows only after a prediction of the policy at least ``margin`` above doing nothing."""
    group = random_groups(12, "train", 0)[11]
    theta, lam = _recorded(group, 12.0)
    raw = _run(MOTIONS["dqn_raw"](group), theta, lam)
    shield = ShieldedMotion(MOTIONS["dqn_raw"](group), adjacency=group.graph, decide_every=0.5, horizon=1.0)
    modes: list[int] = []
    ref = _run(shield, theta, lam, modes)
    following = np.r_[False, np.array(modes[:-1]) == FOLLOW]
    np.testing.assert_array_equal(ref[following], raw[following])
    np.testing.assert_array_equal(ref[~following], theta[~following, group.assisted])
    predictions = np.array(shield.predictions)
    chosen = np.array(shield.choices) == FOLLOW
    assert chosen.any() and not chosen.all()  # the group makes it do both
    assert np.all(predictions[chosen, 1] >= predictions[chosen, 0] + shield.margin)
    # trusted at tick 100 at the earliest, its first prediction done a period later: nothing altered before
    assert not following[:151].any()


def test_it_never_alters_the_participant_before_its_model_is_trusted_and_leaves_a_group_alone_when_told_to():
    """With a margin no prediction can reach, the shielded DQN is doing nothing: r is exactly r without L2."""
    group = TABLE2[1]
    block = ShieldedMotion(MOTIONS["dqn_raw"](group), adjacency=group.graph, margin=1.0)
    with_shield = Simulator(pop_sync(group, motion=block, blender="deliverable")).run(n_steps=501)["r"]
    without = Simulator(pop_sync(group, l2=False)).run(n_steps=501)["r"]
    np.testing.assert_allclose(with_shield, without, rtol=0, atol=1e-12)
    assert len(block.predictions) == 4 and set(block.choices) == {NONE}  # decisions at 200, 300, 400, 500


def test_the_numpy_copy_of_the_network_chooses_as_torch_does():
    policy = DQNPolicy.default()
    fast = policy.predictor()
    assert isinstance(fast, NumpyDQNPolicy)
    rng = np.random.default_rng(2)
    policy.reset(3.0)
    fast.reset(3.0)
    for _ in range(300):
        n = int(rng.integers(3, 12))
        theta = rng.uniform(0, 2 * np.pi, n)
        context = L3Context(0, np.zeros(3), theta, float(rng.uniform(0, 6)), float(rng.uniform(0.5, 1.6)), 3.5, 0)
        with torch.no_grad():
            values = policy.network(torch.as_tensor(policy.observation(context), dtype=torch.float32)).numpy()
        if np.sort(values)[-1] - np.sort(values)[-2] > 1e-4:
            assert fast.act(context) == policy.act(context)


def test_bad_data_policy():
    """A bad tick identifies nothing and asks the policy nothing (its oscillator coasts); doing nothing, θ_ref holds."""
    group = TABLE2[1]
    theta, lam = _recorded(group, 3.0)
    theta[150, 1] = np.nan
    theta[160, 0] = 1e300
    lam[170] = np.inf
    shield = ShieldedMotion(MOTIONS["dqn_raw"](group), adjacency=group.graph, decide_every=0.5, horizon=0.5)
    modes: list[int] = []
    ref = _run(shield, theta, lam, modes)
    assert np.isfinite(ref).all()
    for k in (150, 160):
        if modes[k - 1] == NONE:
            assert ref[k] == ref[k - 1]
    # 299 increments less those ending at or starting from a bad phase (149→150, 150→151, 159→160, 160→161) or λ
    assert shield.count == 299 - 6


def test_the_shielded_network_is_the_default_dqn_and_the_network_alone_is_dqn_raw():
    """(test_sync's Table 3 check on group 1 runs the default, shielded ``dqn``.)"""
    block = MOTIONS["dqn"](TABLE2[1])
    assert isinstance(block, ShieldedMotion) and isinstance(block.ahead.policy, NumpyDQNPolicy)
    assert isinstance(MOTIONS["dqn_raw"](TABLE2[1]), MotionComputer)


def test_constructor_checks():
    with pytest.raises(ValueError, match="ShieldedMotion: motion must be a MotionComputer block, got str"):
        ShieldedMotion("dqn")
    motion = _motion(SteerPolicy(), 3, 0, 1.0, "ring")
    with pytest.raises(ValueError, match=r"ShieldedMotion: margin must be a finite number in \[0.0, inf\), got -0.1"):
        ShieldedMotion(motion, margin=-0.1)
    with pytest.raises(ValueError, match=r"ShieldedMotion: backup must be a finite number in \[0.0, inf\), got -1"):
        ShieldedMotion(motion, backup=-1)


def test_it_wraps_any_motion_computer_and_predicts_it_on_the_predicted_phases():
    """Around the circular mean: the policy row of a prediction is the closed loop with the mean of row 1's own
    predicted phases as θ_ref (an independent loop on SyncModel), and when following, θ_ref is the mean's."""
    rng = np.random.default_rng(6)
    n, assisted, gain = 5, 3, 0.8
    omega, theta, lam = rng.uniform(1.0, 4.0, n), rng.uniform(0, 2 * np.pi, n), 1.3
    a = rng.uniform(0.2, 1.2, (n, n))
    np.fill_diagonal(a, 0.0)
    shield = ShieldedMotion(MeanPhaseMotion(n, assisted), adjacency=a)
    job = shield.start_rollout(theta, lam, (omega, gain), k=0, dt=0.01, steps=120)
    shield.advance_rollout(job, 1000)
    model = SyncModel(omega, gain, a, assisted)
    th, la, total = theta.copy(), np.array(lam), 0.0
    for _ in range(120):
        others = np.delete(th, assisted)
        mean = np.angle(np.exp(1j * others).sum()) % (2 * np.pi)
        seen, _, la = model.blend(th, np.array(mean), la)
        total += float(order_parameter(seen))
        th, _ = model.advance(th, seen, np.array(0.0), np.array(0.0))
    np.testing.assert_allclose(job.scores[1], total / 120, rtol=0, atol=1e-10)

    group = random_groups(12, "train", 0)[11]
    phases, lams = _recorded(group, 8.0)
    block = ShieldedMotion(MeanPhaseMotion(group.n, group.assisted), adjacency=group.graph, decide_every=0.5)
    modes: list[int] = []
    ref = _run(block, phases, lams, modes)
    following = np.r_[False, np.array(modes[:-1]) == FOLLOW]
    mean = _run(MeanPhaseMotion(group.n, group.assisted), phases, lams)
    assert following.any()
    np.testing.assert_array_equal(ref[following], mean[following])


def test_a_snapshot_of_a_shield_continues_bit_for_bit_with_its_wrapped_block_and_its_prediction():
    group = TABLE2[1]
    phases, lams = _recorded(group, 4.0)
    d = Diagram()
    m = d.add("m", ShieldedMotion(MOTIONS["dqn_raw"](group), adjacency=group.graph, decide_every=0.5))
    d.expose_input("theta", m.theta)
    d.expose_input("lam", m.lam)
    d.expose_output("theta_ref", m.theta_ref)
    sim = d.compile(0.01)
    refs = []
    for k in range(400):
        if k == 260:
            snapshot = sim.state_dict()
        refs.append(float(sim.step(theta=phases[k], lam=lams[k])["theta_ref"]))
    assert m.job is not None
    sim.load_state_dict(snapshot)
    again = [float(sim.step(theta=phases[k], lam=lams[k])["theta_ref"]) for k in range(260, 400)]
    assert again == refs[260:]
