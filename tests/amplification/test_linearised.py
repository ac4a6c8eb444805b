"""The linearised solver's cheaper iteration computes what the straightforward formulas compute.

The line search takes values only at its trial points and the gradients at the kept one, :func:`box_qp` starts
from the last multipliers, the members' gradients are one batched product: checked here against independent
NumPy evaluations of the same formulas on the shipped blender's real problems, and against the reference paths;
:func:`box_qp`'s minimiser against an enumeration of the active sets and the KKT conditions, on the real duals too.
"""

import itertools

import numpy as np
import pytest
import torch

from cogblocks.amplification.kinematics import plan_features
from cogblocks.amplification.linearised import LinearisedSolver, box_qp, network_input
from cogblocks.diagrams.amplification import amplification_setup, replay_movement
from cogblocks.diagrams.amplification_setup import OPTIMISED, blender_networks
from tests.amplification.optimal_helpers import plain_blender, random_dual

torch.set_num_threads(1)
ITERATIONS = 12


@pytest.fixture(scope="module")
def captured():
    """The first decisions' problems of the shipped setting (seven networks, kinematic inputs) on a movement."""
    setup = amplification_setup(None, 1)
    settings = {k: v for k, v in OPTIMISED.items() if k != "components"}
    blender = plain_blender(setup.movements, blender_networks(setup.encoder), setup.table, e_des=1,
                             subspace=setup.subspace, **settings)  # fmt: skip
    problems, start = [], LinearisedSolver.start

    def capture(solver, p, w0, *args):
        problems.append((p, np.array(w0), args))
        return start(solver, p, w0, *args)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(LinearisedSolver, "start", capture)
        replay_movement(setup, int(setup.humans[0]), blender)
    assert len(problems) >= 4 and "kinematics" in problems[0][0]
    return blender._linear, blender._stack, problems[:4]


def straightforward(solver, p, w, z_target, delta):
    """The merit at ``w``, the logits, their gradients in the input and its Jacobian in ``w``, from the formulas."""
    kin = p["kinematics"]
    v = kin.velocity(w)
    speed, dt = np.linalg.norm(v, axis=1), kin.dt
    jerk = np.linalg.norm(np.diff(v, n=2, axis=0) / dt**2, axis=1).mean()
    peak, length = int(np.argmax(speed)), len(v)
    features = [speed.max(), peak * dt, length * dt, np.log1p(jerk), speed.mean(), peak / length]  # the judges' six
    x = np.r_[p["x0"] + p["A"] @ w, features]
    pre = solver.w1 @ x + solver.b1
    logits = solver.w2 @ np.maximum(pre, 0.0) + solver.b2
    gradients = (solver.w2 * (pre > 0.0)) @ solver.w1  # the block-diagonal output weights times the whole layer
    _, grads = plan_features(v, kin.dt)
    rows = np.zeros((6, len(w)))
    rows[[0, 3, 4]] = np.einsum("sn,rsa->ran", kin.phi, grads[:, kin.t :]).reshape(3, -1)
    cost = w @ p["H"] @ w + 2.0 * p["q"] @ w
    short = np.maximum(z_target - solver.sign * logits, 0.0).sum()
    excess = max(np.linalg.norm(p["g0"] + p["C"] @ w) - delta, 0.0)
    return cost + 1e3 * (short + excess), logits, gradients, np.vstack([p["A"], rows])


def test_every_iterate_carries_the_straightforward_merit_and_linearisation(captured):
    """After each iteration (no time limit) the run's merit and linearisation at its iterate, taken lazily (values at
    the trial points, gradients at the kept one), are the formulas' at that iterate, to 1e-9 relative."""
    solver, _, problems = captured
    assert solver.gradient == "blocks"  # the shipped default
    for p, w0, args in problems:
        run = solver.start(p, w0, *args)
        z_target, delta = run.z_target, run.delta
        for k in range(1, ITERATIONS + 1):
            run.max_iter = k
            run.run(1.0, clock=lambda: 0.0)
            merit, logits, gradients, jacobian = straightforward(solver, p, run.w, z_target, delta)
            z, g, jac = run._linear
            assert run.merit == pytest.approx(merit, rel=1e-9)
            np.testing.assert_allclose(z, logits, rtol=1e-9, atol=1e-9)
            np.testing.assert_allclose(g, gradients, rtol=0, atol=1e-9 * np.abs(gradients).max())
            np.testing.assert_allclose(jac, jacobian, rtol=0, atol=1e-9 * np.abs(jacobian).max())
            if run.finished:
                break


def test_values_without_gradients_are_the_same_numbers(captured):
    """The line search's values (no gradients) are bit for bit those of the full evaluation."""
    solver, _, problems = captured
    rng = np.random.default_rng(0)
    for p, w0, _ in problems:
        w = w0 + rng.normal(size=len(w0))
        x, jacobian = network_input(p, w)
        bare, none = network_input(p, w, jacobian=False)
        assert none is None and np.array_equal(bare, x) and jacobian.shape == (66, len(w))
        np.testing.assert_array_equal(solver.logits(x, gradient=False)[0], solver.logits(x)[0])
        v = p["kinematics"].velocity(w)
        np.testing.assert_array_equal(plan_features(v, 0.01, gradient=False)[0], plan_features(v, 0.01)[0])
        assert plan_features(v, 0.01, gradient=False)[1] is None


def test_the_fast_path_plans_as_the_stacked_reference(captured):
    """The whole solve (40 iterations at most, no time limit): the same statuses, iterations and kept plans as with
    the stacked gradients (the straightforward product), to 1e-9 relative."""
    fast, stack, problems = captured
    reference = LinearisedSolver(stack.w1, stack.b1, stack.w2, stack.b2, fast.sign, gradient="stacked")
    for p, w0, args in problems:
        runs = [solver.start(p, w0, *args) for solver in (fast, reference)]
        for run in runs:
            run.run(1.0, clock=lambda: 0.0)
        (best, status, done), (best_ref, status_ref, done_ref) = (run.result() for run in runs)
        assert (status, done) == (status_ref, done_ref) and (best is None) == (best_ref is None)
        if best is not None:
            np.testing.assert_allclose(best, best_ref, rtol=0, atol=1e-9 * np.abs(best_ref).max())
        np.testing.assert_allclose(runs[0].w, runs[1].w, rtol=0, atol=1e-9 * np.abs(runs[1].w).max())


@pytest.mark.parametrize("seed", range(30))
def test_box_qp_from_a_start_is_the_same_minimiser(seed):
    """From any start (inside, outside or at the bounds) the active-set method ends at the minimiser it reaches
    from zero (unique: box_qp's ridge makes the dual strictly convex)."""
    rng = np.random.default_rng(seed)
    m, b, upper = random_dual(rng, (2, 11), (0, 6), 0.7)
    r = len(b)
    cold = box_qp(m, b, upper)
    starts = [rng.normal(size=r) * 2.0, cold + rng.normal(size=r) * 1e-3, np.minimum(cold, 1e6), np.full(r, 1e3)]
    for start in starts:
        np.testing.assert_allclose(box_qp(m, b, upper, start), cold, rtol=0, atol=1e-9 * (1.0 + np.abs(cold).max()))


def enumerated_minimiser(m, b, upper):
    """The box QP's minimiser by trying every split of the variables into at zero, at the upper bound and free (3^r
    linear solves with NumPy): the feasible stationary point of the least objective, independent of box_qp's path."""
    r, best = len(b), (np.inf, None)
    for split in itertools.product(range(3), repeat=r):
        lam = np.where(np.array(split) == 1, upper, 0.0)
        if np.any(np.isinf(lam)):
            continue
        free = np.array(split) == 2
        if free.any():
            lam[free] = np.linalg.solve(m[np.ix_(free, free)], b[free] - m[np.ix_(free, ~free)] @ lam[~free])
        if np.all(lam >= -1e-12) and np.all(lam <= upper + 1e-12):
            value = 0.5 * lam @ m @ lam - b @ lam
            if value < best[0]:
                best = (value, lam)
    return best[1]


def assert_kkt(m, b, upper, lam):
    """Within the bounds, with the objective's gradient zero on the free variables and pointing out of the box on the
    bound ones (to 1e-8 of the problem's scale)."""
    grad = m @ lam - b
    tol = 1e-8 * (1.0 + np.abs(b).max() + np.abs(m).max() * np.abs(lam).max())
    assert np.all(lam >= 0.0) and np.all(lam <= upper)
    at_zero, at_upper = lam <= 0.0, lam >= upper
    free = ~at_zero & ~at_upper
    assert np.all(np.abs(grad[free]) <= tol)
    assert np.all(grad[at_zero] >= -tol) and np.all(grad[at_upper] <= tol)


@pytest.mark.parametrize("seed", range(40))
def test_box_qp_is_the_enumerated_minimiser(seed):
    """On random definite duals of 1–6 variables (free blocks of every size box_qp solves, the closed forms for one
    and two included), cold and from a start: the KKT point that enumerating the active sets finds, to 1e-9."""
    rng = np.random.default_rng(100 + seed)
    m, b, upper = random_dual(rng, (1, 7), (1, 5), 0.6)
    r = len(b)
    expected = enumerated_minimiser(m, b, upper)
    for start in (None, rng.normal(size=r)):
        lam = box_qp(m, b, upper, start)
        assert_kkt(m, b, upper, lam)
        np.testing.assert_allclose(lam, expected, rtol=0, atol=1e-9 * (1.0 + np.abs(expected).max()))


def test_box_qp_meets_the_kkt_conditions_on_the_captured_duals(captured):
    """Every dual the captured solves pose (7–10 variables, 12 iterations at most) gets a KKT point."""
    solver, _, problems = captured
    duals = []

    def checked(m, b, upper, start=None):
        lam = box_qp(m, b, upper, start)
        duals.append((m, b, upper, lam))
        return lam

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr("cogblocks.amplification.linearised.box_qp", checked)
        for p, w0, args in problems:
            run = solver.start(p, w0, *args)
            run.max_iter = ITERATIONS
            run.run(1.0, clock=lambda: 0.0)
    assert len(duals) >= 2 * len(problems) and max(len(b) for _, b, _, _ in duals) >= 8
    for m, b, upper, lam in duals:
        assert_kkt(m, b, upper, lam)
