"""The optimised blender emitting its plan (``emit="plan"``), the terminal guard and its options (a human at rest
predicted to stay so, ``guard_rest``; a reserve of δ_pos, ``guard_margin``), and the planned-vs-emitted replay."""

import numpy as np
import pytest
import torch

from cogblocks.amplification.emission import final_gap, guard_settings, guarded_velocity, rebased
from cogblocks.diagrams.amplification import amplification_setup, replay_movement
from cogblocks.diagrams.amplification_setup import blender_networks
from studies.amplification_gap import RecordingBlender, planned_vs_emitted, summarise
from studies.amplification_inner import inner_setup
from tests.amplification.optimal_helpers import eta_i_options, plain_blender

torch.set_num_threads(1)
DT = 0.01
REST = 1.0


def replay(setup, blender, human):
    # the rule's emission itself, without the limiter that smooths it
    return replay_movement(setup, human, blender, probes={"nearest": "l2.nearest"}, step_limit=None)


def random_case(seed, t=25, end=40, n=60):
    rng = np.random.default_rng(seed)
    past = rng.normal(scale=50.0, size=(n, 3))
    altered, human = past.copy(), past + rng.normal(scale=30.0, size=(n, 3))
    altered[t:] = human[t:] = 0.0
    return t, end, altered, human, rng.normal(scale=40.0, size=(n, 3)), rng.normal(scale=200.0, size=(n, 3))


@pytest.mark.parametrize("seed", range(4))
def test_final_gap_is_the_summed_replay(seed):
    t, end, altered, human, plan, basis = random_case(seed)
    v_h, v_a = basis[t] + 3.0, basis[t] + plan[t] - 7.0
    # an independent replay: this tick, then the plan on the basis until the end, then the human alone
    a, h = altered.copy(), human.copy()
    a[t], h[t] = v_a, v_h
    a[t + 1 : end] = basis[t + 1 : end] + plan[t + 1 : end]
    h[t + 1 :] = basis[t + 1 :]
    a[end:] = 0.0
    np.testing.assert_allclose(final_gap(t, v_a, v_h, altered, human, plan, basis, end, DT), DT * (a - h).sum(0))


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("delta", [5.0, 1e6])
def test_guard_keeps_the_final_gap_within_delta(seed, delta):
    t, end, altered, human, plan, basis = random_case(seed)
    start = np.linalg.norm(final_gap(t, basis[t] + plan[t], basis[t], altered, human, plan, basis, end, DT))
    guarded = []
    for s in range(t, end):  # the human follows the basis: only the guard may change the emission
        v, g = guarded_velocity(s, basis[s], altered, human, plan, basis, end, DT, delta)
        altered[s], human[s] = v, basis[s]
        guarded.append(g)
    human[end:] = basis[end:]
    final = np.linalg.norm(DT * (altered - human).sum(0))
    if start <= delta:  # within delta: the plan itself is emitted, untouched
        assert not any(guarded)
        np.testing.assert_allclose(altered[t:end], basis[t:end] + plan[t:end], rtol=0, atol=1e-12)
        assert final == pytest.approx(start)
    else:
        assert any(guarded) and final <= delta + 1e-9


def test_guard_passes_bad_data_through():
    t, end, altered, human, plan, basis = random_case(0)
    v, guarded = guarded_velocity(t, np.array([np.nan, 0.0, 0.0]), altered, human, plan, basis, end, DT, 5.0)
    assert guarded and np.isnan(v[0])


def test_rebased_keeps_the_emission_continuous():
    rng = np.random.default_rng(3)
    plan, basis, predicted = (rng.normal(size=(30, 3)) for _ in range(3))
    phi0 = np.linspace(0.9, 0.0, 10)
    held, anchor, emitted = rng.normal(size=3), rng.normal(size=3), rng.normal(size=3)
    new_plan, new_basis = rebased(plan.copy(), basis, predicted, 12, phi0, held, emitted, anchor)
    np.testing.assert_array_equal(new_basis[:12], basis[:12])
    np.testing.assert_array_equal(new_basis[12:], predicted[12:])
    np.testing.assert_allclose(new_plan[12:22] - plan[12:22], np.outer(phi0, emitted - anchor - held))
    np.testing.assert_array_equal(new_plan[22:], plan[22:])
    # the held correction is now the one actually emitted at t0 − 1, against the prediction there
    unchanged, _ = rebased(plan.copy(), basis, predicted, 12, phi0, held, None, anchor)
    np.testing.assert_array_equal(unchanged, plan)


@pytest.mark.parametrize("e_des", [1, 0])
def test_emitted_movement_is_the_last_plan(e_des):
    setup = amplification_setup(None, e_des)
    networks = blender_networks(setup.encoder)
    blender = RecordingBlender(
        setup.movements, networks, setup.table, e_des=e_des, subspace=setup.subspace, **eta_i_options(emit="plan")
    )
    trace = replay(setup, blender, int(setup.humans[0]))
    v_a = np.asarray(trace["v_a"], dtype=np.float64)
    committed = [i for i, r in enumerate(blender.results) if r.status in ("converged", "accepted")]
    assert committed
    ticks = [blender.results[i].tick + blender.solve_ticks - 1 for i in committed] + [len(v_a)]
    for k, i in enumerate(committed):  # between commits the block emits what the commit's check classified
        window = [s for s in range(ticks[k], ticks[k + 1]) if s not in blender.guarded_ticks]
        np.testing.assert_allclose(v_a[window], blender.checked[i][window], rtol=0, atol=1e-9)
    last, t0, end = blender.results[committed[-1]], ticks[-2], blender.end
    assert not [s for s in blender.guarded_ticks if s >= t0]
    # independently of the block's records: the library's prediction at the decision plus the plan in force
    nearest = int(trace["nearest"][last.tick])
    moving = np.linalg.norm(trace["v_h"][last.tick - 1]) > 1.0
    expected = setup.movements.velocity[nearest, t0:end] * moving + blender.plan[t0:end]
    np.testing.assert_allclose(v_a[t0:end], expected, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(v_a[end:], 0.0)
    # so the constrained networks classify the emitted movement exactly as the last check did
    eps = blender.member_eps(v_a)
    assert (eps.min() if e_des else eps.max()) == pytest.approx(last.eps, abs=1e-9)


def test_option_off_is_the_old_emission():
    setup = amplification_setup(None, 1)
    networks = blender_networks(setup.encoder, profile=2, kinematic=0)
    settings = eta_i_options(iterations=10, emit="human")
    blender = plain_blender(setup.movements, networks, setup.table, subspace=setup.subspace, **settings)
    assert "basis" not in blender.state_dict() and blender.emit == "human"
    trace = replay(setup, blender, int(setup.humans[0]))
    # after the last commit the plan's correction is added to the measured human, nothing else
    tail = [r.tick + blender.solve_ticks - 1 for r in blender.results if r.status in ("converged", "accepted")][-1]
    np.testing.assert_allclose(
        trace["v_a"][tail : blender.end], trace["v_h"][tail : blender.end] + blender.plan[tail : blender.end]
    )
    assert not blender.guarded_ticks
    with pytest.raises(ValueError, match="emit"):
        plain_blender(setup.movements, networks, emit="predicted")


def test_planned_vs_emitted_replay():
    rows = planned_vs_emitted(inner_setup(1), 2, time_limit_ms=1000.0)
    assert len(rows) == 2 and all(r["planned"] is not None for r in rows)
    summary = summarise(rows, 1)
    assert summary["n"] == 2 and set(summary["feature_abs_diff"]) >= {"peak_speed", "duration"}
    assert 0.0 <= summary["emitted"]["all_members"] <= 1.0


def test_summarise_counts_flips():
    def row(planned, emitted, features):
        return {
            "planned": {"members": planned, "ensemble": 0, "kinematic": 1, "features": [0.0] * 6, "max_abs_diff": 2.0},
            "emitted": {"members": emitted, "ensemble": -1, "kinematic": 0, "features": features},
            "guarded_ticks": 1,
        }

    rows = [row([0.01, 0.02], [0.01, 0.5], [1.0] * 6), row([0.01, 0.02], [0.0, 0.0], [3.0] * 6)]
    out = summarise(rows, 0)
    assert out["planned"]["all_members"] == 1.0 and out["emitted"]["all_members"] == 0.5 and out["flipped"] == 1
    assert out["planned"]["ensemble_judge"] == 1.0 and out["emitted"]["ensemble_judge"] == 0.0
    assert out["feature_abs_diff"]["peak_speed"] == {"p50": 2.0, "p90": pytest.approx(2.8)}
    assert out["guarded_ticks"] == 2


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
def removal_setup():
    return amplification_setup(None, 0)


def guard_replay(setup, **extra):
    """The first removal human replayed through the optimised blender with ``extra`` options."""
    blender = plain_blender(setup.movements, blender_networks(setup.encoder), setup.table, e_des=0,
                             subspace=setup.subspace, **eta_i_options(**extra))  # fmt: skip
    return blender, replay_movement(setup, int(setup.humans[0]), blender)


def test_guard_options_leave_the_human_emission_alone(removal_setup):
    plain, plain_trace = guard_replay(removal_setup, emit="human", guard_rest=False)
    guarded, trace = guard_replay(removal_setup, emit="human", guard_rest=True, guard_margin=19.0)
    assert (guarded.guard_rest, guarded.guard_margin) == (True, 19.0)
    np.testing.assert_array_equal(trace["v_a"], plain_trace["v_a"])
    assert not plain.guarded_ticks and not guarded.guarded_ticks


def test_guard_margin_moves_the_tail_guard_bound(removal_setup):
    tail, tail_trace = guard_replay(removal_setup, emit="tail")
    tight, trace = guard_replay(removal_setup, emit="tail", guard_margin=19.9)  # the guard bounds the gap at 0.1 mm
    t0 = min(t for t in tight.guarded_ticks)
    # the same plans up to the tail; the tail guarded, and only the tail (the last plan emits itself)
    np.testing.assert_array_equal(trace["v_a"][:t0], tail_trace["v_a"][:t0])
    assert tight.guarded_ticks and max(tight.guarded_ticks) < tight.end
    assert len(tight.guarded_ticks) > len(tail.guarded_ticks)
    assert tight.end - t0 <= tight.knot_spacing
