"""The eighth round's options of the optimised blender: the last plan emitted as planned (``emit="tail"``), a
removal margin and the prediction decisions are made on."""

import dataclasses
import math

import numpy as np
import pytest
import torch

from cogblocks.amplification.plan import library_prediction
from cogblocks.diagrams.amplification import amplification_setup, replay_movement
from cogblocks.diagrams.amplification_setup import blender_networks
from studies.amplification_gap import RecordingBlender
from tests.amplification.optimal_helpers import PredictionRecorder, eta_i_options, plain_blender

torch.set_num_threads(1)


def replay(setup, networks, human, **extra):
    blender = RecordingBlender(
        setup.movements, networks, setup.table, e_des=setup.e_des, subspace=setup.subspace, **eta_i_options(**extra)
    )
    # the rule's emission itself, without the limiter that smooths it
    trace = replay_movement(setup, human, blender, probes={"nearest": "l2.nearest"}, step_limit=None)
    return blender, trace


def commits(blender):
    """Indices of the committed decisions and their commit ticks."""
    index = [i for i, r in enumerate(blender.results) if r.status in ("converged", "accepted")]
    return index, [blender.results[i].tick + blender.solve_ticks - 1 for i in index]


@pytest.mark.parametrize("rank", [0, 1])
def test_tail_emits_the_last_plan_as_it_was_checked(setup, networks, rank):
    human = int(setup.humans[rank])
    plain, plain_trace = replay(setup, networks, human, emit="human")
    tail, trace = replay(setup, networks, human, emit="tail")
    index, ticks = commits(tail)
    t0, end, last = ticks[-1], tail.end, tail.results[index[-1]]
    assert commits(plain)[1] == ticks and plain.end == end and end - t0 <= tail.knot_spacing
    assert tail.as_planned == 1
    # up to the last commit nothing differs from emit="human": the same plans, the same emission
    untimed = [[dataclasses.replace(r, solve_ms=0.0) for r in b.results[: index[-1]]] for b in (plain, tail)]
    assert untimed[0] == untimed[1]
    np.testing.assert_array_equal(trace["v_a"][:t0], plain_trace["v_a"][:t0])
    # from it: the last decision's prediction plus the correction emit="human" adds to the human, with the
    # prediction's error on the sample before t0 held by the first knot's weight (re-anchored: v_a continuous)
    decision = last.tick
    moving = np.linalg.norm(trace["v_h"][decision - 1]) > tail.rest_speed
    b = setup.movements.velocity[int(trace["nearest"][decision])] * moving
    second_knot = min(t0 - 1 + tail.knot_spacing, end - 1)  # the first knot's weight falls to 0 at the next knot
    phi0 = np.interp(np.arange(t0, end), [t0 - 1, second_knot], [1.0, 0.0])
    error = trace["v_h"][t0 - 1] - b[t0 - 1]
    expected = b[t0:end] + plain.plan[t0:end] + phi0[:, None] * error
    free = [s for s in range(t0, end) if s not in tail.guarded_ticks]
    np.testing.assert_allclose(trace["v_a"][free], expected[np.subtract(free, t0)], rtol=0, atol=1e-9)
    np.testing.assert_array_equal(trace["v_a"][end:], 0.0)
    # no guard on these movements: the constrained networks see the emitted movement as the last check did
    assert free == list(range(t0, end))
    eps = tail.member_eps(np.asarray(trace["v_a"], dtype=np.float64))
    assert (eps.min() if setup.e_des else eps.max()) == pytest.approx(last.eps, abs=1e-9)


def test_earlier_plans_emit_the_human(setup, networks):
    tail, trace = replay(setup, networks, int(setup.humans[0]), emit="tail")
    index, ticks = commits(tail)
    assert len(ticks) >= 3
    v_h = np.asarray(trace["v_h"], dtype=np.float64)
    # each earlier plan ends more than knot_spacing samples after its commit: until the next commit it emits
    # v_h + u, u being its check's movement less the decision's prediction (the library movement)
    for k, i in enumerate(index[:-1]):
        assert tail.end - ticks[k] > tail.knot_spacing
        decision = tail.results[i].tick
        moving = np.linalg.norm(v_h[decision - 1]) > tail.rest_speed
        b = setup.movements.velocity[int(trace["nearest"][decision])] * moving
        window = np.arange(ticks[k], ticks[k + 1])
        u = tail.checked[i][window] - b[window]
        np.testing.assert_allclose(trace["v_a"][window], v_h[window] + u, rtol=0, atol=1e-9)
    assert not [s for s in tail.guarded_ticks if s < ticks[-1]]


@pytest.mark.parametrize("seed", range(4))
def test_library_prediction(seed):
    rng = np.random.default_rng(seed)
    velocity, human = rng.normal(scale=90.0, size=(2, 60, 3))
    t = int(rng.integers(1, 50))
    expected = np.zeros((60, 3))
    expected[t - 1 :] = velocity[t - 1 :]  # the library movement from the last measured sample on
    np.testing.assert_array_equal(library_prediction(velocity, human, t), expected)
    np.testing.assert_array_equal(library_prediction(velocity, human, t, moving=False), 0.0)  # a human at rest


def test_decisions_plan_on_the_library_prediction(setup, networks):
    blender = PredictionRecorder(
        setup.movements, networks, setup.table, e_des=setup.e_des, subspace=setup.subspace, **eta_i_options()
    )
    trace = replay_movement(setup, int(setup.humans[0]), blender, probes={"nearest": "l2.nearest"})
    v_h = np.asarray(trace["v_h"], dtype=np.float64)
    for decision, predicted in blender.predictions:
        b = setup.movements.velocity[int(trace["nearest"][decision])]
        expected = np.zeros_like(b)
        if np.linalg.norm(v_h[decision - 1]) > blender.rest_speed:  # the library movement; a human at rest stays so
            expected[decision:] = b[decision:]
        np.testing.assert_allclose(predicted, expected, rtol=0, atol=1e-9)
    assert len(blender.predictions) >= 3
    # and the check of the last committed plan is the emitted past, then that prediction plus the plan
    index, ticks = commits(blender)
    t0, end = ticks[-1], blender.end
    last = dict(blender.predictions)[blender.results[index[-1]].tick]
    np.testing.assert_allclose(blender.checked[index[-1]][t0:end], last[t0:end] + blender.plan[t0:end], atol=1e-9)


def test_removal_margin_sets_the_removal_target_only(setup, networks):
    blender = plain_blender(setup.movements, networks, setup.table, e_des=setup.e_des, removal_margin=0.09999,
                             **{k: v for k, v in eta_i_options().items() if "margin" not in k})  # fmt: skip
    margin = 0.09999 if setup.e_des == 0 else 0.05  # encoding fear keeps ``margin`` (its default here)
    assert blender._z_target == pytest.approx(math.log((0.9 + margin) / (0.1 - margin)))
    others = {"e_des": setup.e_des, "solver": "linearised"}
    assert plain_blender(setup.movements, networks, margin=0.02, **others).removal_margin == 0.02
    with pytest.raises(ValueError, match="removal_margin"):
        plain_blender(setup.movements, networks, removal_margin=0.1, **others)
    with pytest.raises(ValueError, match="emit"):
        plain_blender(setup.movements, networks, emit="last", **others)


def test_removal_plans_meet_the_removal_margin():
    setup = amplification_setup(None, 0)
    networks = blender_networks(setup.encoder)
    human = int(setup.humans[0])
    logits = {}
    for margin in (None, 0.09999):
        # without a removal margin the block removes fear with ``margin``, here 0.099 (ε̂ ≤ 0.001)
        blender, _ = replay(setup, networks, human, margin=0.099, removal_margin=margin, solve_ticks=1)
        index = commits(blender)[0]
        eps = np.array([blender.results[i].eps for i in index])
        converged = np.array([blender.results[i].status == "converged" for i in index])
        logits[margin] = np.log(eps / (1.0 - eps)), converged
    # with one tick the check is the solver's own problem: a converged plan is at its target, the cheapest one
    target = math.log(0.00001 / 0.99999)  # −11.5, against −6.9 for ε̂ ≤ 0.001
    z, converged = logits[0.09999]
    assert converged.any() and np.all(z[converged] <= target + 1e-3) and np.median(z) <= target + 0.5
    z, converged = logits[None]
    assert converged.any() and np.all(np.abs(z[converged] - math.log(0.001 / 0.999)) <= 0.5)
