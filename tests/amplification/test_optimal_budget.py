"""The linearised solver's cost per iteration: the members' gradients by blocks and the iteration-time prediction."""

import numpy as np
import pytest
import torch

from cogblocks.amplification.linearised import LinearisedRun, LinearisedSolver
from cogblocks.diagrams.amplification import amplification_setup, replay_movement
from cogblocks.diagrams.amplification_setup import blender_networks
from tests.amplification.optimal_helpers import options, plain_blender

torch.set_num_threads(1)


def random_solver(rng, hidden=(5, 7, 4), inputs=6, **options):
    """Stacked members of unequal hidden sizes, as :class:`StackedNetworks` lays them out."""
    w1 = rng.normal(size=(sum(hidden), inputs))
    b1 = rng.normal(size=sum(hidden))
    w2 = [rng.normal(size=h) for h in hidden]
    return LinearisedSolver(w1, b1, w2, rng.normal(size=len(hidden)), 1.0, **options), (w1, b1, w2)


@pytest.mark.parametrize("hidden", [(5, 7, 4), (6, 6, 6)])  # padded blocks; blocks viewing the stacked layer
@pytest.mark.parametrize("gradient", ["stacked", "blocks"])
def test_gradients_are_each_members_own(gradient, hidden):
    """Against each member computed on its own: Σ_h w2_h·[pre_h > 0]·w1_h over its hidden units only."""
    rng = np.random.default_rng(3)
    solver, (w1, b1, w2) = random_solver(rng, hidden=hidden, gradient=gradient)
    assert np.shares_memory(solver._own, solver.w1) == (len(set(hidden)) == 1)
    x = rng.normal(size=w1.shape[1])
    logits, gradients = solver.logits(x)
    start = 0
    for k, w in enumerate(w2):
        rows = slice(start, start + len(w))
        pre = w1[rows] @ x + b1[rows]
        assert logits[k] == pytest.approx(w @ np.maximum(pre, 0.0) + solver.b2[k], abs=1e-12)
        np.testing.assert_allclose(gradients[k], (w * (pre > 0.0)) @ w1[rows], rtol=0, atol=1e-12)
        start += len(w)


def test_block_gradients_plan_as_the_stacked_ones():
    """Without a binding time limit the two ways give the same decisions (the same numbers to rounding)."""
    setup = amplification_setup(None, 1)
    networks = blender_networks(setup.encoder)
    settings = options()
    results = {}
    for gradient in ("stacked", "blocks"):
        blender = plain_blender(
            setup.movements, networks, setup.table, e_des=1, subspace=setup.subspace, gradient=gradient, **settings
        )
        replay_movement(setup, int(setup.humans[0]), blender)
        results[gradient] = blender.results
    assert [r.status for r in results["blocks"]] == [r.status for r in results["stacked"]]
    np.testing.assert_allclose([r.eps for r in results["blocks"]], [r.eps for r in results["stacked"]], atol=1e-9)
    assert [r.end for r in results["blocks"]] == [r.end for r in results["stacked"]]


def toy_problem(rng, solver, m=3):
    """A small problem for ``solver`` (its inputs affine in ``m`` plan variables, no terminal or speed limit)."""
    inputs = solver.w1.shape[1]
    return {"A": rng.normal(size=(inputs, m)), "x0": rng.normal(size=inputs), "H": np.eye(m), "q": np.zeros(m),
            "C": np.zeros((3, m)), "g0": np.zeros(3), "d": np.zeros(m), "rhs": [1.0, 5.0, -1e6, 20.0]}  # fmt: skip


@pytest.mark.parametrize("predict_setup, predicted_ms, iterations", [(True, 7.0, 1), (False, 2.0, 2)])
def test_the_prediction_leaves_out_the_preparation_when_asked(monkeypatch, predict_setup, predicted_ms, iterations):
    """On a clock where the preparation costs 5 ms and an iteration's line search 2 ms, 3.5 ms are left after the
    first iteration: counting the preparation predicts 7 ms for the next one, which does not start; leaving it out,
    2 ms, which does (and no third)."""
    clock = {"now": 0.0}
    rng = np.random.default_rng(0)
    solver, _ = random_solver(rng, predict_setup=predict_setup)
    prepare, line_search = LinearisedRun._prepare, LinearisedSolver._line_search

    def costly_prepare(run):
        clock["now"] += 5e-3
        return prepare(run)

    def costly_search(self, *args):
        clock["now"] += 2e-3
        return line_search(self, *args)

    monkeypatch.setattr(LinearisedRun, "_prepare", costly_prepare)
    monkeypatch.setattr(LinearisedSolver, "_line_search", costly_search)
    run = solver.start(toy_problem(rng, solver), np.zeros(3), 5.0, 2.2, 20.0, 20.0, max_iter=10)
    run.run(10.5e-3, clock=lambda: clock["now"])
    assert solver.iteration * 1e3 == pytest.approx(predicted_ms)
    assert run.done == iterations


@pytest.mark.parametrize(
    "options, message",
    [({"gradient": "dense"}, "gradient must be one of"), ({"predict_setup": "no"}, "predict_setup must be True or")],
)
def test_bad_values_are_refused_by_name(options, message):
    setup = amplification_setup(None, 1)
    with pytest.raises(ValueError, match=f"OptimalBlender: {message}"):
        plain_blender(setup.movements, setup.encoder, setup.table, solver="linearised", **options)
    with pytest.raises(ValueError, match=message):
        random_solver(np.random.default_rng(0), **options)
