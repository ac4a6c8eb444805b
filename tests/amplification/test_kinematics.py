"""The optimised blender constraining networks with kinematic inputs (``mlp_kinematic``)."""

import copy

import numpy as np
import pytest
import torch

from cogblocks.amplification.encoder import EncoderNet, resampling_matrix
from cogblocks.amplification.judges import (
    BLENDER_ENSEMBLE,
    BLENDER_KINEMATIC_ENSEMBLE,
    EncoderEnsemble,
    ensemble_inputs,
    kinematic_features,
    load_ensemble,
)
from cogblocks.amplification.kinematics import PlanKinematics, plan_features
from cogblocks.amplification.linearised import network_input
from cogblocks.amplification.members import kinematic_member
from cogblocks.amplification.plan import plan_problem
from cogblocks.diagrams.amplification import amplification_setup
from cogblocks.diagrams.amplification_setup import CONSTRAINED_MEMBERS, blender_ensembles, blender_networks
from tests.amplification.optimal_helpers import plain_blender

torch.set_num_threads(1)
DT = 0.01


@pytest.fixture(scope="module")
def setup():
    return amplification_setup()


@pytest.fixture(scope="module")
def kinematic():
    return load_ensemble(BLENDER_KINEMATIC_ENSEMBLE)


def smooth_plan(seed: int, length: int = 70, t: int = 20, knots: int = 5) -> tuple[PlanKinematics, np.ndarray]:
    """A plan whose speeds stay far from zero and whose peak is clear: no kink near ``w``."""
    rng = np.random.default_rng(seed)
    s = np.linspace(0.0, 1.0, length)
    base = np.outer(np.sin(np.pi * s) * 400.0 + 30.0, [0.6, 0.7, 0.3]) + rng.normal(size=(length, 3)) * 5.0
    return PlanKinematics(base, t, rng.random((length - t, knots)), DT), rng.normal(size=3 * knots) * 0.1


@pytest.mark.parametrize("seed", range(5))
def test_features_are_the_judges_features(seed):
    plan, w = smooth_plan(seed)
    v = plan.velocity(w)
    padded = np.vstack([v, np.zeros((30, 3))])  # the judges restrict a padded movement to its duration
    np.testing.assert_allclose(plan(w)[0], kinematic_features(padded, DT), rtol=1e-13, atol=1e-13)
    np.testing.assert_array_equal(plan_features(v, DT)[0], plan(w)[0])


@pytest.mark.parametrize("seed", range(5))
def test_feature_jacobian_is_the_finite_difference(seed):
    plan, w = smooth_plan(seed)
    values, jacobian = plan(w)
    step = 1e-6
    numeric = np.stack([(plan(w + step * e)[0] - plan(w - step * e)[0]) / (2 * step) for e in np.eye(len(w))], axis=1)
    assert np.all(np.isclose(numeric[[1, 5]], 0.0))  # the peak did not move: away from the kink
    np.testing.assert_allclose(jacobian, numeric, rtol=1e-5, atol=1e-7)
    assert np.all(jacobian[[1, 2, 5]] == 0.0) and np.all(np.abs(jacobian[[0, 3, 4]]).max(axis=1) > 0.0)


def test_resting_samples_give_no_gradient_and_no_nan():
    base = np.zeros((40, 3))
    base[5:30, 0] = 100.0  # a flat plateau: zero jerk inside it, zero speed outside
    plan = PlanKinematics(base, 10, np.zeros((30, 3)), DT)
    values, jacobian = plan(np.zeros(9))
    assert np.all(np.isfinite(values)) and np.all(np.isfinite(jacobian))
    empty = PlanKinematics(np.zeros((3, 3)), 0, np.ones((3, 1)), DT)
    assert np.all(np.isfinite(empty(np.zeros(3))[1]))


def test_profile_only_problems_keep_their_input_map(setup):
    lib = setup.library
    v = lib.velocity[int(setup.humans[0])]
    rhs = [1.0, 6.9, 5.0, 15.0]
    plain = plan_problem(10, 90, v, v, v, v, 10, lib.dt, rhs)
    x, jacobian = network_input(plain, np.ones(3 * len(plain["knots"])))
    assert "kinematics" not in plain and jacobian is plain["A"] and x.shape == (60,)
    with_kinematics = plan_problem(10, 90, v, v, v, v, 10, lib.dt, rhs, kinematics=True)
    x, jacobian = network_input(with_kinematics, np.ones(3 * len(plain["knots"])))
    assert x.shape == (66,) and jacobian.shape == (66, plain["A"].shape[1])
    np.testing.assert_array_equal(x[60:], with_kinematics["kinematics"](np.ones(3 * len(plain["knots"])))[0])


def test_member_eps_is_the_ensemble_prediction(setup, kinematic):
    networks = [copy.deepcopy(n).double() for n in kinematic]  # double precision on both sides
    blender = plain_blender(setup.movements, networks, solver="linearised")
    ensemble = EncoderEnsemble(networks)
    assert ensemble.architecture == "mlp_kinematic"
    lib = setup.library
    for index in setup.val[:6]:
        v = lib.velocity[index]
        length = int(lib.length[index])
        profile = (resampling_matrix(length) @ v[:length]).T.reshape(1, -1)
        expected = ensemble.predict(ensemble_inputs(profile, v[None], lib.dt, "mlp_kinematic"))[0]
        assert abs(blender.member_eps(v).mean() - expected) <= 1e-9


def test_mixed_members_weigh_what_each_takes(setup, kinematic):
    blender = plain_blender(setup.movements, [setup.encoder, kinematic[0]], solver="linearised")
    v = setup.library.velocity[int(setup.val[0])]
    eps = blender.member_eps(v)
    alone = [
        plain_blender(setup.movements, n, solver="linearised").member_eps(v)[0] for n in (setup.encoder, kinematic[0])
    ]
    np.testing.assert_allclose(eps, alone, rtol=1e-12)


def kinematic_eps(network: EncoderNet, velocity: np.ndarray, padded: int) -> float:
    """ε̂ of a kinematic network for a planned velocity (L, 3), by an independent (torch) forward pass."""
    movement = np.vstack([velocity, np.zeros((padded - len(velocity), 3))])
    profile = (resampling_matrix(len(velocity)) @ velocity).T.reshape(1, -1)
    return float(network.predict(ensemble_inputs(profile, movement[None], DT, "mlp_kinematic"))[0])


@pytest.mark.parametrize("e_des", [1, 0])
def test_solver_meets_the_kinematic_member(e_des, kinematic):
    setup = amplification_setup(None, e_des)
    member = kinematic[0]
    blender = plain_blender(setup.movements, [setup.encoder, member], setup.table, e_des=e_des,
                             subspace=setup.subspace, solver="linearised")  # fmt: skip
    lib, t = setup.library, 10
    rhs = [blender._sign, blender._z_target, blender.end_speed, blender._delta]
    for human in setup.humans[:10]:  # the first movement whose prediction the member does not decide as e_des
        past = np.zeros((lib.max_len, 3))
        past[:t] = lib.velocity[human, :t]
        predicted = np.zeros_like(past)
        predicted[t:] = lib.velocity[human, t:]
        length = min(int(lib.length[human]) + 10, lib.max_len)
        problem = plan_problem(t, length, predicted, past, past, past, 10, lib.dt, rhs, setup.subspace, 1000.0, True)
        w0 = np.zeros(3 * len(problem["knots"]))
        start = kinematic_eps(member, problem["kinematics"].velocity(w0), lib.max_len)
        if (start <= 0.9) if e_des == 1 else (start >= 0.1):
            break
    else:
        pytest.fail("every prediction already meets the member: no test")
    run = blender._linear.start(problem, w0, blender._z_target, blender._z_clip, blender._delta, blender.delta_pos, 40)
    run.run(np.inf)
    best, status, _ = run.result()
    assert best is not None and status in ("converged", "accepted")
    planned = problem["kinematics"].velocity(best)
    eps = kinematic_eps(member, planned, lib.max_len)
    assert eps > 0.9 if e_des == 1 else eps < 0.1, (start, eps)
    padded = np.vstack([planned, np.zeros((lib.max_len - length, 3))])
    assert abs(blender.member_eps(padded)[1] - eps) <= 1e-5  # float32 torch against the float64 solver


def test_bad_members(setup, kinematic):
    with pytest.raises(ValueError, match="networks with kinematic inputs need solver='linearised'"):
        plain_blender(setup.movements, [setup.encoder, kinematic[0]])
    with pytest.raises(ValueError, match="got 50 inputs"):
        kinematic_member(EncoderNet(n_inputs=50, hidden=2))
    shape = EncoderNet(n_inputs=66, hidden=2)
    shape.checkpoint = {"architecture": "mlp_shape_kinematic"}
    with pytest.raises(ValueError, match="architecture 'mlp_shape_kinematic'"):
        plain_blender(setup.movements, [setup.encoder, shape], solver="linearised")
    assert kinematic_member(kinematic[0]) and not kinematic_member(setup.encoder)


def test_shipped_blender_networks(setup):
    networks = blender_networks(setup.encoder)
    sizes = [n.hidden.in_features for n in networks]
    assert networks[0] is setup.encoder
    assert sizes == [60] * (1 + CONSTRAINED_MEMBERS["profile"]) + [66] * CONSTRAINED_MEMBERS["kinematic"]
    assert [n.hidden.in_features for n in blender_networks(setup.encoder, 1, 0)] == [60, 60]


def test_blender_ensembles_take_the_kinematic_networks_of_every_file(setup, kinematic):
    profile, networks = blender_ensembles((BLENDER_KINEMATIC_ENSEMBLE, BLENDER_KINEMATIC_ENSEMBLE))
    assert len(profile) == len(load_ensemble(BLENDER_ENSEMBLE)) and len(networks) == 2 * len(kinematic)
    for net, same in zip(networks, [*kinematic, *kinematic], strict=True):
        for a, b in zip(net.state_dict().values(), same.state_dict().values(), strict=True):
            assert torch.equal(a, b)
    chosen = blender_networks(setup.encoder, 1, 6, ensembles=(profile, networks))
    assert [n.hidden.in_features for n in chosen] == [60, 60] + [66] * 6
