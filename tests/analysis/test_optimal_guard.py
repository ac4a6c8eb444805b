"""The ninth round's options of the terminal guard: a human at rest predicted to stay so (``guard_rest``) and a
reserve of δ_pos (``guard_margin``)."""

import numpy as np
import pytest
import torch

from cogblocks.amplification import OptimalBlender
from cogblocks.amplification.emission import final_gap, guard_settings, guarded_velocity
from cogblocks.diagrams.amplification import amplification_setup, replay_movement
from cogblocks.diagrams.amplification_setup import OPTIMISED, blender_networks

torch.set_num_threads(1)
DT = 0.01
REST = 1.0


def random_case(seed, t=25, end=40, n=60):
    """A past up to ``t``, a correction and a basis moving well beyond the plan's ``end``."""
    rng = np.random.default_rng(seed)
    past = rng.normal(scale=50.0, size=(n, 3))
    altered, human = past.copy(), past + rng.normal(scale=30.0, size=(n, 3))
    altered[t:] = human[t:] = 0.0
    return t, end, altered, human, rng.normal(scale=40.0, size=(n, 3)), rng.normal(scale=200.0, size=(n, 3))


@pytest.mark.parametrize("seed", range(4))
def test_final_gap_at_rest_is_the_summed_replay(seed):
    t, end, altered, human, plan, basis = random_case(seed)
    v_h, v_a = np.zeros(3), basis[t] + plan[t] - 7.0
    # an independent replay: this tick, then the plan on its basis until the end, the human never moving again
    a, h = altered.copy(), human.copy()
    a[t], a[t + 1 : end], a[end:] = v_a, basis[t + 1 : end] + plan[t + 1 : end], 0.0
    h[t:] = 0.0
    gap = final_gap(t, v_a, v_h, altered, human, plan, basis, end, DT, at_rest=True)
    np.testing.assert_allclose(gap, DT * (a - h).sum(0))


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("delta", [5.0, 15.0, 1e6])
def test_guard_at_rest_keeps_a_resting_human_within_delta(seed, delta):
    t, end, altered, human, plan, basis = random_case(seed)
    start = np.linalg.norm(final_gap(t, basis[t] + plan[t], np.zeros(3), altered, human, plan, basis, end, DT, True))
    guarded = []
    for s in range(t, end):  # the human at rest from t on: only the guard may change the emission
        v, g = guarded_velocity(s, np.zeros(3), altered, human, plan, basis, end, DT, delta, REST)
        altered[s], human[s] = v, 0.0
        guarded.append(g)
    final = np.linalg.norm(DT * (altered - human).sum(0))
    if start <= delta:  # within delta: the plan itself is emitted, untouched
        assert not any(guarded)
        np.testing.assert_allclose(altered[t:end], basis[t:end] + plan[t:end], rtol=0, atol=1e-12)
        assert final == pytest.approx(start)
    else:
        assert any(guarded) and final <= delta + 1e-9


def test_guard_without_the_rest_rule_lets_a_resting_human_drift():
    # the same resting human under the prediction's guard: it believes the human will follow the basis, and the
    # final gap ends beyond delta on some case where the rest rule keeps it within (the test above)
    beyond = []
    for seed in range(6):
        t, end, altered, human, plan, basis = random_case(seed)
        for s in range(t, end):
            altered[s], _ = guarded_velocity(s, np.zeros(3), altered, human, plan, basis, end, DT, 15.0)
            human[s] = 0.0
        beyond.append(np.linalg.norm(DT * (altered - human).sum(0)) > 15.0 + 1e-6)
    assert any(beyond)


@pytest.mark.parametrize("seed", range(4))
def test_rest_rule_waits_for_the_human_to_stop(seed):
    t, end, altered, human, plan, basis = random_case(seed)
    for v_h in (basis[t], np.array([REST + 1e-3, 0.0, 0.0])):  # moving: the prediction's guard, bit for bit
        for delta in (5.0, 1e6):
            rule = guarded_velocity(t, v_h, altered, human, plan, basis, end, DT, delta, REST)
            plain = guarded_velocity(t, v_h, altered, human, plan, basis, end, DT, delta)
            np.testing.assert_array_equal(rule[0], plain[0])
            assert rule[1] == plain[1]


class Owner:
    delta_pos, rest_speed = 20.0, 1.0


def test_guard_settings():
    assert guard_settings(Owner(), False, 0.0) == (False, 0.0, 20.0, None)
    assert guard_settings(Owner(), True, 2.5) == (True, 2.5, 17.5, 1.0)
    with pytest.raises(ValueError, match=r"Owner: guard_margin must be a finite number in \[0.0, 20.0\), got 20.0"):
        guard_settings(Owner(), True, 20.0)
    with pytest.raises(ValueError, match="Owner: guard_rest must be True or False, got 1"):
        guard_settings(Owner(), 1, 0.0)


@pytest.fixture(scope="module")
def setup():
    return amplification_setup(None, 0)


def replay(setup, **extra):
    settings = {k: v for k, v in OPTIMISED.items() if k != "components"}
    blender = OptimalBlender(setup.movements, blender_networks(setup.encoder), setup.table, e_des=0,
                             subspace=setup.subspace, **{**settings, "time_limit_ms": 1000.0, **extra})  # fmt: skip
    return blender, replay_movement(setup, int(setup.humans[0]), blender)


def test_guard_options_leave_the_human_emission_alone(setup):
    plain, plain_trace = replay(setup, emit="human", guard_rest=False)
    guarded, trace = replay(setup, emit="human", guard_rest=True, guard_margin=19.0)
    assert (guarded.guard_rest, guarded.guard_margin) == (True, 19.0)
    np.testing.assert_array_equal(trace["v_a"], plain_trace["v_a"])
    assert not plain.guarded_ticks and not guarded.guarded_ticks


def test_guard_margin_moves_the_tail_guard_bound(setup):
    tail, tail_trace = replay(setup, emit="tail")
    tight, trace = replay(setup, emit="tail", guard_margin=19.9)  # the guard bounds the gap at 0.1 mm
    t0 = min(t for t in tight.guarded_ticks)
    # the same plans up to the tail; the tail guarded, and only the tail (the last plan emits itself)
    np.testing.assert_array_equal(trace["v_a"][:t0], tail_trace["v_a"][:t0])
    assert tight.guarded_ticks and max(tight.guarded_ticks) < tight.end
    assert len(tight.guarded_ticks) > len(tail.guarded_ticks)
    assert tight.end - t0 <= tight.knot_spacing
