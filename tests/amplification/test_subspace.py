"""The optimised blender's realism subspace and its sequential-QP solver on the exact ReLU networks."""

import numpy as np
import pytest
import torch
from scipy.optimize import minimize

from cogblocks.amplification.encoder import movement_length
from cogblocks.amplification.judges import BLENDER_ENSEMBLE, load_ensemble
from cogblocks.amplification.linearised import box_qp
from cogblocks.amplification.plan import plan_problem
from cogblocks.amplification.subspace import load_subspace, movement_subspace
from cogblocks.data.features import classifier_inputs, resample_movement
from cogblocks.diagrams.amplification import DELTA_POS_MM, amplification_setup, replay_movement
from cogblocks.diagrams.amplification_setup import OPTIMISED
from tests.amplification.optimal_helpers import plain_blender, random_dual

torch.set_num_threads(1)


@pytest.fixture(scope="module")
def setup():
    return amplification_setup()


@pytest.fixture(scope="module")
def networks(setup):
    return [setup.encoder, *load_ensemble(BLENDER_ENSEMBLE)]


def test_subspace_is_the_pca_of_the_class(setup, tmp_path):
    lib = setup.movements
    sub = movement_subspace(lib, 0, 5)
    inputs = classifier_inputs(lib)[~lib.fear]
    np.testing.assert_allclose(sub.mean, inputs.mean(axis=0), atol=1e-9)
    np.testing.assert_allclose(sub.components @ sub.components.T, np.eye(5), atol=1e-9)
    # the leading direction maximises the variance: no other unit direction of the class explains more
    centred = inputs - sub.mean
    first = np.var(centred @ sub.components[0])
    for d in np.random.default_rng(0).normal(size=(20, 60)):
        assert np.var(centred @ (d / np.linalg.norm(d))) <= first + 1e-9
    total = (centred**2).sum()
    assert sub.explained == pytest.approx(((centred @ sub.components.T) ** 2).sum() / total)
    # residual: zero in the subspace, the norm of an orthogonal offset outside it
    inside = sub.mean + np.array([3.0, -2.0, 1.0, 0.5, 7.0]) @ sub.components
    orthogonal = np.linalg.svd(np.vstack([sub.components, np.eye(60)[:1]]))[2][-1]
    assert sub.residual(inside) == pytest.approx(0.0, abs=1e-9)
    assert sub.residual(inside + 4.0 * orthogonal) == pytest.approx(4.0)
    sub.save(tmp_path / "s.npz")
    again = load_subspace(tmp_path / "s.npz")
    np.testing.assert_array_equal(again.components, sub.components)
    assert again.e_des == 0 and again.explained == sub.explained


def test_penalty_is_the_squared_residual(setup):
    sub = movement_subspace(setup.movements, 1, 8)
    rng = np.random.default_rng(1)
    a, x0 = rng.normal(size=(60, 12)) * 50.0, sub.mean + rng.normal(size=60) * 100.0
    h, q = sub.penalty(a, x0)
    for w in rng.normal(size=(5, 12)):
        assert w @ h @ w + 2 * q @ w + sub.residual(x0) ** 2 == pytest.approx(sub.residual(x0 + a @ w) ** 2)


def test_subspace_bad_input(setup, tmp_path):
    with pytest.raises(ValueError, match="at least as many movements of class e_des=1, the library has"):
        movement_subspace(setup.movements, 1, 10_000)
    with pytest.raises(ValueError, match="e_des"):
        movement_subspace(setup.movements, 2)
    np.savez(tmp_path / "bad.npz", mean=np.zeros(60))
    with pytest.raises(ValueError, match="bad.npz: not a MovementSubspace file .missing components, e_des, explained"):
        load_subspace(tmp_path / "bad.npz")
    with pytest.raises(ValueError, match="subspace must be a MovementSubspace of 60 inputs for e_des=0"):
        plain_blender(setup.movements, setup.encoder, e_des=0, subspace=movement_subspace(setup.movements, 1))


@pytest.mark.parametrize("seed", range(40))
def test_box_qp_is_the_minimiser(seed):
    rng = np.random.default_rng(seed)
    m, b, upper = random_dual(rng, (1, 6), (0, 3), 0.5)
    r = len(b)
    lam = box_qp(m, b, upper)
    assert np.all(lam >= 0.0) and np.all(lam <= upper)
    reference = minimize(
        lambda x: 0.5 * x @ m @ x - b @ x, np.zeros(r), jac=lambda x: m @ x - b, method="L-BFGS-B",
        bounds=[(0.0, u if np.isfinite(u) else None) for u in upper], options={"ftol": 1e-15, "gtol": 1e-12},
    )  # fmt: skip
    assert 0.5 * lam @ m @ lam - b @ lam <= reference.fun + 1e-7 * (1.0 + abs(reference.fun))


def test_linearised_logits_are_the_networks(setup, networks):
    blender = plain_blender(setup.movements, networks, solver="linearised")
    solver = blender._linear
    x = setup.encoder.mean.double().numpy() + np.random.default_rng(2).normal(size=60) * 200.0
    z, grad = solver.logits(x)
    xt = torch.tensor(x, dtype=torch.float32, requires_grad=True)
    for k, net in enumerate(networks):
        logit = net.out(torch.relu(net.preactivation(xt))).squeeze()
        (expected,) = torch.autograd.grad(logit, xt)
        assert z[k] == pytest.approx(logit.item(), abs=1e-4)
        np.testing.assert_allclose(grad[k], expected.numpy(), rtol=1e-4, atol=1e-6)


def replay(setup, blender, human):
    return replay_movement(setup, human, blender)


@pytest.mark.parametrize("e_des", [1, 0])
def test_realistic_plan_meets_every_member(e_des, networks):
    setup = amplification_setup(None, e_des)
    options = {**OPTIMISED, "time_limit_ms": 1000.0}
    options.pop("components")
    blender = plain_blender(setup.movements, networks, setup.table, e_des=e_des, subspace=setup.subspace, **options)
    human = int(setup.humans[1])
    trace = replay(setup, blender, human)
    altered = trace["v_a"]
    inputs = resample_movement(altered, movement_length(altered, 1.0))
    eps = np.array([float(n.predict(inputs)) for n in networks])  # an independent (torch) forward pass
    assert np.all(eps > 0.9) if e_des == 1 else np.all(eps < 0.1), eps
    assert np.linalg.norm(trace["p_a"][-1] - trace["p_h"][-1]) <= DELTA_POS_MM
    assert blender.fallbacks == 0 and "fallback" not in {r.status for r in blender.results}
    # the penalty keeps the altered movement nearer realistic movements of the class than the bare plan
    bare = plain_blender(setup.movements, networks, setup.table, e_des=e_des, solver="linearised", time_limit_ms=1e3)
    bare_altered = replay(setup, bare, human)["v_a"]
    bare_inputs = resample_movement(bare_altered, movement_length(bare_altered, 1.0))
    assert setup.subspace.residual(inputs) < setup.subspace.residual(bare_inputs)


def test_out_of_time_falls_back_to_the_table(setup, networks):
    blender = plain_blender(
        setup.movements, networks, setup.table, subspace=setup.subspace, solver="linearised", time_limit_ms=1e-6
    )
    human = int(setup.humans[0])
    trace = replay(setup, blender, human)
    statuses = [r.status for r in blender.results]
    # one iteration always runs; an out-of-time decision keeps a plan only if it is acceptable
    assert blender.fallbacks == statuses.count("fallback")
    for r in blender.results:
        if r.status == "accepted":
            assert r.eps > 0.9 and r.distance_mm <= DELTA_POS_MM
    assert np.all(np.isfinite(trace["v_a"]))


class TickClock:
    """A clock that advances 1 ms at every reading: the budget logic counted in readings, not wall time."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        self.now += 1e-3
        return self.now


def first_problem(setup, networks):
    """A blender and the problem of a decision at tick 10 of a held-out movement (its own future as the prediction)."""
    blender = plain_blender(setup.movements, networks, setup.table, subspace=setup.subspace, solver="linearised")
    lib, human, t = setup.library, int(setup.humans[0]), 10
    past = np.zeros((lib.max_len, 3))
    past[:t] = lib.velocity[human, :t]
    predicted = np.zeros_like(past)
    predicted[t:] = lib.velocity[human, t:]
    length = min(int(lib.length[human]) + 10, lib.max_len)
    rhs = [1.0, blender._z_target, blender.end_speed, blender._delta]
    problem = plan_problem(t, length, predicted, past, past, past, 10, lib.dt, rhs, setup.subspace, 1000.0)
    return blender, problem, np.zeros(3 * len(problem["knots"]))


def test_a_solve_spread_over_calls_is_the_solve_in_one_go(setup, networks):
    blender, problem, w0 = first_problem(setup, networks)
    solver = blender._linear
    args = (problem, w0, blender._z_target, blender._z_clip, blender._delta, blender.delta_pos, 6)
    whole = solver.start(*args)
    assert whole.run(np.inf, clock=TickClock())
    clock, pieces, calls = TickClock(), solver.start(*args), 0
    while not pieces.finished:
        solver.iteration = 0.0
        before = pieces.done
        pieces.run(clock.now + 2.5e-3, clock=clock)  # room for one iteration (two readings) per call
        assert pieces.done - before == 1
        calls += 1
    assert calls == whole.done
    best, status, done = pieces.result()
    np.testing.assert_array_equal(best, whole.result()[0])
    assert (status, done) == whole.result()[1:]


def test_no_iteration_starts_past_the_budget(setup, networks):
    blender, problem, w0 = first_problem(setup, networks)
    solver = blender._linear
    run = solver.start(problem, w0, blender._z_target, blender._z_clip, blender._delta, blender.delta_pos, 10)
    clock = TickClock()
    solver.iteration = 0.0
    # each iteration reads the clock twice (1 ms each): started at 1, 3, then 5 + 1 would pass the 5.5 ms deadline
    run.run(5.5e-3, clock=clock)
    assert run.done == 2 and solver.iteration == pytest.approx(1e-3)
    assert not run.run(clock.now + 0.5e-3, clock=clock) and run.done == 2  # no room: nothing runs
    run.run(clock.now + 0.5e-3, clock=clock, at_least_one=True)
    assert run.done == 3


@pytest.mark.parametrize("ticks", [1, 4])
def test_solve_ticks_plans_from_the_last_tick(setup, networks, ticks):
    blender = plain_blender(
        setup.movements, networks, setup.table, subspace=setup.subspace, solver="linearised",
        time_limit_ms=1e3, solve_ticks=ticks, iterations=30,
    )  # fmt: skip
    trace = replay(setup, blender, int(setup.humans[0]))
    solved = [r for r in blender.results if r.status != "ended"]
    assert solved and all(1 <= r.ticks <= ticks for r in blender.results)
    first = solved[0].tick
    # before the first plan takes effect (tick first + ticks − 1) the human velocity passes through
    np.testing.assert_array_equal(trace["v_a"][: first + ticks - 1], trace["v_h"][: first + ticks - 1])
    assert not np.allclose(trace["v_a"][first + ticks - 1], trace["v_h"][first + ticks - 1])
    # ticks that worked: at least the first and the committing one of each decision, never more than it spanned
    assert sum(min(r.ticks, 2) for r in solved) <= len(blender.tick_ms) <= sum(r.ticks for r in solved)
    np.testing.assert_allclose(blender.solve_ms, [r.solve_ms for r in solved])
    with pytest.raises(ValueError, match="solve_ticks > 1 needs solver='linearised'"):
        plain_blender(setup.movements, networks, setup.table, solve_ticks=2)


def test_ticks_run_blas_on_one_thread(setup, networks):
    # OpenBLAS's threads would wait for busy cores: a tick's products run on the calling thread, and the
    # process's setting is back once the tick is over
    from threadpoolctl import threadpool_info, threadpool_limits

    def blas_threads() -> set[int]:
        return {info["num_threads"] for info in threadpool_info() if info["user_api"] == "blas"}

    blender = plain_blender(setup.movements, networks, setup.table, solver="linearised", solve_ticks=2)
    seen, work = [], blender._work
    blender._work = lambda t, started: (seen.append(blas_threads()), work(t, started))[1]
    with threadpool_limits(limits=2, user_api="blas"):
        replay_movement(setup, int(setup.humans[0]), blender)
        assert blas_threads() == {2}
    assert blender.results and len(seen) >= len(blender.results)
    assert all(threads == {1} for threads in seen)
