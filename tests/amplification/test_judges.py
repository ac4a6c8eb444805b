"""Independent judges of the PoP of Amplification and the ensemble-constrained optimised blender."""

import numpy as np
import pytest
import torch

from cogblocks.amplification import EncoderNet, NoCorrection
from cogblocks.amplification.encoder import clip_decision, movement_length
from cogblocks.amplification.encoder_casadi import encoder_to_casadi, ensemble_logits
from cogblocks.amplification.judges import (
    BLENDER_ENSEMBLE,
    JUDGE_ENSEMBLE,
    EncoderEnsemble,
    Judges,
    KinematicJudge,
    ensemble_inputs,
    kinematic_features,
    load_ensemble,
)
from cogblocks.data.features import resample_movement
from cogblocks.data.reach import generate_reach_library
from cogblocks.diagrams.amplification import amplification_judges, amplification_setup, pop_amplification
from cogblocks.sim import Simulator
from cogblocks.training.judges import train_judges
from cogblocks.training.recipe import TrainingRecipe
from tests.amplification.optimal_helpers import plain_blender

torch.set_num_threads(1)


@pytest.fixture(scope="module")
def setup():
    return amplification_setup()


def test_kinematic_features_of_a_triangle_profile():
    dt = 0.01
    speed = np.r_[np.linspace(0.0, 500.0, 31), np.linspace(490.0, 10.0, 49)]  # peak at sample 30, 80 samples
    velocity = np.zeros((100, 3))
    velocity[:80] = np.outer(speed, [0.6, 0.8, 0.0])
    features = kinematic_features(velocity, dt)
    # the first sample (speed 0) counts in the duration: the restriction ends at the last moving sample
    jerk = np.abs(np.diff(speed, n=2)) / dt**2
    expected = [500.0, 0.30, 0.80, np.log1p(jerk.mean()), speed.mean(), 30 / 80]
    np.testing.assert_allclose(features, expected, rtol=1e-12)
    assert np.array_equal(kinematic_features(np.zeros((50, 3)), dt), np.zeros(6))
    both = kinematic_features(np.stack([velocity, np.zeros((100, 3))]), dt)
    np.testing.assert_allclose(both[0], expected, rtol=1e-12)


def test_kinematic_judge_separates_held_out_movements(setup):
    train, val = setup.movements, setup.library.subset(setup.val)
    judge = KinematicJudge(setup.library.dt).fit(train.velocity, train.fear)
    accuracy = np.mean((judge.predict(val.velocity) > 0.5) == val.fear)
    assert accuracy > 0.7  # a real classifier of held-out movements, not a coin
    with pytest.raises(ValueError, match="both fear and no-fear"):
        KinematicJudge(0.01).fit(train.velocity[:3], np.ones(3, dtype=bool))


def test_judges_decide_as_the_clipping_rule_on_the_mean(setup):
    judges = amplification_judges()
    lib = setup.library.subset(setup.val[:12])
    decisions = judges.decide(lib.velocity)
    rows = []
    for v in lib.velocity:
        n = movement_length(v, 1.0)
        rows.append(resample_movement(v, n))  # the spline fit itself, not the shared linear map
    inputs = np.array(rows)
    if judges.ensemble.architecture == "mlp_kinematic":  # the shipped judges also take the kinematic features
        inputs = np.hstack([inputs, [kinematic_features(v, lib.dt) for v in lib.velocity]])
    members = [net.predict(inputs) for net in judges.ensemble.networks]
    np.testing.assert_array_equal(decisions["ensemble"], clip_decision(np.mean(members, axis=0)))
    np.testing.assert_array_equal(decisions["kinematic"], (judges.kinematic.predict(lib.velocity) > 0.5).astype(int))


def test_shipped_ensembles_are_disjoint_and_reproducible(setup):
    blender, judges = load_ensemble(BLENDER_ENSEMBLE), load_ensemble(JUDGE_ENSEMBLE)
    assert len(judges) == 5 and len(blender) >= 1
    weights = [n.hidden.weight.detach().numpy() for n in [setup.encoder, *blender, *judges]]
    for i in range(len(weights)):
        for j in range(i):  # networks of different inputs (judges with kinematic features) differ anyway
            assert weights[i].shape != weights[j].shape or not np.allclose(weights[i], weights[j])
    assert all(n.hidden.in_features == 66 for n in judges) and judges[0].checkpoint["architecture"] == "mlp_kinematic"
    assert judges[0].checkpoint["role"] == "judges"
    # the judges' training is seeded: a tiny run twice gives the same networks
    config = TrainingRecipe(epochs=1)
    small = generate_reach_library(3, n_subjects=2, n_fear=15, n_no_fear=15)
    a = train_judges(small, np.arange(24), config, seed=0, members=2, log=None)
    b = train_judges(small, np.arange(24), config, seed=0, members=2, log=None)
    assert torch.equal(a[0].hidden.weight, b[0].hidden.weight)
    assert not torch.equal(a[0].hidden.weight, a[1].hidden.weight)


def test_ensemble_logits_are_each_networks_logit(setup):
    networks = [setup.encoder, *load_ensemble(BLENDER_ENSEMBLE)]
    x = np.random.default_rng(1).normal(size=60) * setup.encoder.scale.numpy() + setup.encoder.mean.numpy()
    stacked = np.asarray(ensemble_logits(networks)(x)).ravel()
    single = [float(encoder_to_casadi(n, logit=True)(x)) for n in networks]
    np.testing.assert_allclose(stacked, single, rtol=1e-9, atol=1e-9)


def test_optimal_blender_meets_every_member(setup):
    networks = [setup.encoder, *load_ensemble(BLENDER_ENSEMBLE)]
    assert len(networks) >= 2
    human = int(setup.humans[0])
    lib = setup.library
    blender = plain_blender(setup.movements, networks, setup.table)
    d = pop_amplification(
        (lib.velocity[human], lib.position[human]), setup.movements, table=setup.table, encoder=setup.encoder,
        corrector=NoCorrection(), blending=blender,
    )  # fmt: skip
    trace = Simulator(d).run(n_steps=lib.max_len)
    altered = trace["v_a"]
    eps = [float(n.predict(resample_movement(altered, movement_length(altered, 1.0)))) for n in networks]
    solved = [r for r in blender.results if r.status in ("converged", "accepted")]
    assert solved, "no plan was made"
    # the planned ε̂ is the least favourable member's; the emitted movement meets the clipping rule for all
    assert min(eps) > 0.9, eps
    assert len(blender.multipliers) == len(networks) + 3


def test_optimal_blender_rejects_a_bad_ensemble(setup):
    with pytest.raises(ValueError, match="non-empty list of them, got 0 items"):
        plain_blender(setup.movements, [], setup.table)
    with pytest.raises(ValueError, match="got 2 items of types EncoderNet, str"):
        plain_blender(setup.movements, [setup.encoder, "net"], setup.table)


def test_encoder_ensemble_is_the_mean():
    torch.manual_seed(0)
    nets = [EncoderNet(hidden=8), EncoderNet(hidden=8)]
    ensemble = EncoderEnsemble(nets)
    x = np.random.default_rng(0).normal(size=(4, 60))
    np.testing.assert_allclose(ensemble.predict(x), (nets[0].predict(x) + nets[1].predict(x)) / 2)
    assert len(Judges(ensemble, KinematicJudge(0.01)).ensemble) == 2
    with pytest.raises(ValueError, match="non-empty"):
        EncoderEnsemble([])
    with pytest.raises(ValueError, match="'mlp_kinematic' networks take 66 inputs, got \\[60\\]"):
        EncoderEnsemble(nets, architecture="mlp_kinematic")


def test_ensemble_inputs_append_the_kinematic_features():
    library = generate_reach_library(3, n_subjects=1, n_fear=2, n_no_fear=2)
    profile = np.random.default_rng(0).normal(size=(4, 60))
    np.testing.assert_array_equal(ensemble_inputs(profile, library.velocity, library.dt), profile)
    np.testing.assert_array_equal(ensemble_inputs(profile, library.velocity, library.dt, "cnn"), profile)
    features = np.array([kinematic_features(v, library.dt) for v in library.velocity])
    plain = ensemble_inputs(profile, library.velocity, library.dt, "mlp_kinematic")
    np.testing.assert_array_equal(plain, np.hstack([profile, features]))
    shape = ensemble_inputs(profile, library.velocity, library.dt, "mlp_shape_kinematic")
    np.testing.assert_allclose(shape[:, :60], profile / features[:, :1])
    torch.manual_seed(0)
    wide = [EncoderNet(n_inputs=66, hidden=4)]
    ensemble = EncoderEnsemble(wide, architecture="mlp_kinematic")
    np.testing.assert_allclose(ensemble.predict(plain), wide[0].predict(plain))
