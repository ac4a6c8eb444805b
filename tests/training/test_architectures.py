"""Candidate encoder architectures and inputs (cogblocks.training.architectures)."""

import numpy as np
import pytest
import torch

from cogblocks.amplification.encoder import EncoderNet
from cogblocks.amplification.encoder_casadi import encoder_to_casadi
from cogblocks.amplification.judges import kinematic_features
from cogblocks.data.features import classifier_inputs
from cogblocks.data.reach import generate_reach_library
from cogblocks.training.architectures import (
    ARCHITECTURES,
    ConvEncoder,
    GRUEncoder,
    architecture_inputs,
    as_encoder_net,
    build_network,
)
from cogblocks.training.judges import train_blender_ensemble, train_blender_kinematic, train_judges
from cogblocks.training.recipe import TrainingRecipe, cross_validate_recipe, train_fold_ensemble, train_member

torch.set_num_threads(1)


@pytest.fixture(scope="module")
def small():
    library = generate_reach_library(3, n_subjects=2, n_fear=15, n_no_fear=15)
    return library, classifier_inputs(library)


def _conv_by_hand(net: ConvEncoder, x: np.ndarray) -> np.ndarray:
    """ε̂ of one input row with the convolution written out as sums (zero padding)."""
    w = net.conv.weight.detach().double().numpy()  # (channels, 3, kernel)
    b = net.conv.bias.detach().double().numpy()
    profile = ((x - net.mean.double().numpy()) / net.scale.double().numpy()).reshape(3, 20)
    half = w.shape[2] // 2
    padded = np.pad(profile, ((0, 0), (half, half)))
    hidden = np.array([[np.sum(w[c] * padded[:, t : t + w.shape[2]]) + b[c] for t in range(20)] for c in range(len(w))])
    z = net.out.weight.detach().double().numpy()[0] @ np.maximum(hidden, 0).reshape(-1) + float(net.out.bias.detach())
    return 1 / (1 + np.exp(-z))


def test_conv_encoder_is_a_convolution_and_exports_to_an_encoder_net(small):
    library, inputs = small
    net, _ = train_member(inputs, library.fear, TrainingRecipe(epochs=3, batch_size=8, hidden=4, architecture="cnn"), 1)
    assert isinstance(net, ConvEncoder)
    eps = net.predict(inputs[:4])
    np.testing.assert_allclose(eps, [_conv_by_hand(net, x) for x in inputs[:4]], rtol=1e-5, atol=1e-6)
    dense = net.to_encoder_net()
    assert isinstance(dense, EncoderNet) and dense.hidden.out_features == 4 * 20
    np.testing.assert_allclose(dense.predict(inputs), net.predict(inputs), rtol=1e-5, atol=1e-6)
    # the blender's casadi model of the exported network is the same function
    f = encoder_to_casadi(dense)
    np.testing.assert_allclose([float(f(x)) for x in inputs[:3]], eps[:3], rtol=1e-5, atol=1e-6)
    # a banded first layer: a filter at point t sees only the points within the kernel's reach
    w1 = dense.hidden.weight.detach().numpy().reshape(4, 20, 3, 20).transpose(0, 1, 3, 2)  # filter, t, s, axis
    t, s = np.meshgrid(np.arange(20), np.arange(20), indexing="ij")
    assert np.all(w1[:, np.abs(t - s) > 2] == 0)


def test_gru_encoder_reads_the_profile_in_time_order(small):
    library, inputs = small
    net, _ = train_member(inputs, library.fear, TrainingRecipe(epochs=2, batch_size=8, hidden=4, architecture="gru"), 2)
    assert isinstance(net, GRUEncoder)
    x = torch.as_tensor(inputs[:3], dtype=torch.float32)
    steps = ((x - net.mean) / net.scale).reshape(3, 3, 20)
    h = torch.zeros(3, 4)
    cell = torch.nn.GRUCell(3, 4)
    cell.load_state_dict({k.replace("_l0", ""): v for k, v in net.gru.state_dict().items()})
    with torch.no_grad():
        for t in range(20):
            h = cell(steps[:, :, t], h)
        expected = torch.sigmoid(net.out(h)).squeeze(-1).double().numpy()
    np.testing.assert_allclose(net.predict(inputs[:3]), expected, rtol=1e-5, atol=1e-6)


def test_architecture_inputs_append_kinematic_features(small):
    library, inputs = small
    for name in ("mlp", "cnn", "gru"):
        assert np.array_equal(architecture_inputs(name, inputs, library.velocity, library.dt), inputs)
    features = kinematic_features(library.velocity, library.dt)
    both = architecture_inputs("mlp_kinematic", inputs, library.velocity, library.dt)
    np.testing.assert_array_equal(both, np.hstack([inputs, features]))
    shape = architecture_inputs("mlp_shape_kinematic", inputs, library.velocity, library.dt)
    np.testing.assert_allclose(shape[:, :60] * features[:, :1], inputs)
    np.testing.assert_array_equal(shape[:, 60:], features)
    assert isinstance(build_network("mlp_kinematic", 66, 8, 0.0), EncoderNet)
    with pytest.raises(ValueError, match="unknown architecture 'lstm'"):
        architecture_inputs("lstm", inputs, library.velocity, library.dt)
    with pytest.raises(ValueError, match="architecture must be one of"):
        TrainingRecipe(architecture="lstm")
    with pytest.raises(ValueError, match="kernel must be odd"):
        ConvEncoder(kernel=4)


@pytest.mark.parametrize("name", ARCHITECTURES)
def test_every_architecture_cross_validates(small, name):
    library, profile = small
    inputs = architecture_inputs(name, profile, library.velocity, library.dt)
    recipe = TrainingRecipe(epochs=2, batch_size=16, hidden=4, architecture=name)
    rows = np.arange(len(library))
    row = cross_validate_recipe(inputs, library.fear, rows, recipe, seed=1, folds=3, members=2)
    assert -1.0 <= row["score"] <= 1.0 and 0.0 <= row["accuracy"] <= 1.0
    if name != "mlp":  # seeded: the same row again (the MLP's is checked in test_judge_recipe)
        assert row == cross_validate_recipe(inputs, library.fear, rows, recipe, seed=1, folds=3, members=2)


def test_judges_of_the_cnn_and_kinematic_recipes_and_judge_only_candidates(small):
    library, inputs = small
    recipe = TrainingRecipe(epochs=2, batch_size=16, hidden=3, architecture="cnn")
    judges = train_judges(library, np.arange(24), recipe, seed=0, members=2, log=None)
    assert all(isinstance(n, EncoderNet) and n.hidden.out_features == 3 * 20 for n in judges)
    # the same networks as training the members directly and exporting them
    direct = train_fold_ensemble(inputs, library.fear, np.arange(24), recipe, fold_seed=0, torch_seed=9000, members=2)
    for judge, conv in zip(judges, direct, strict=True):
        np.testing.assert_allclose(judge.predict(inputs), conv.predict(inputs), rtol=1e-5, atol=1e-6)
    blender = train_blender_ensemble(library, np.arange(24), recipe, seed=0, members=1, log=None)
    assert isinstance(blender[0], EncoderNet)
    with pytest.raises(ValueError, match="GRUEncoder of 60 inputs .* neither the blender's nor a shipped judge"):
        as_encoder_net(GRUEncoder(hidden=2), judge=True)
    wide = EncoderNet(n_inputs=66, hidden=2)
    with pytest.raises(
        ValueError, match="EncoderNet of 66 inputs is no EncoderNet of the 60 profile inputs; it can be only"
    ):
        as_encoder_net(wide)
    assert as_encoder_net(wide, judge=True) is wide
    # the judges of a kinematic recipe take the 66 inputs of architecture_inputs
    kinematic = TrainingRecipe(epochs=1, batch_size=16, hidden=3, architecture="mlp_kinematic")
    wide_judges = train_judges(library, np.arange(24), kinematic, seed=0, members=2, log=None)
    assert all(n.hidden.in_features == 66 for n in wide_judges)


def test_blender_kinematic_members_are_bagged_and_seeded(small):
    library, _ = small
    recipe = TrainingRecipe(epochs=2, batch_size=16, hidden=3, architecture="mlp_kinematic")
    rows = np.arange(24)
    members = train_blender_kinematic(library, rows, recipe, seed=0, members=2, log=None)
    assert all(isinstance(n, EncoderNet) and n.hidden.in_features == 66 for n in members)
    # member i: the rows without fold i (fold seed 1000), torch seed 7100 + i
    inputs = architecture_inputs("mlp_kinematic", classifier_inputs(library), library.velocity, library.dt)
    direct = train_fold_ensemble(inputs, library.fear, rows, recipe, fold_seed=1000, torch_seed=7100, members=2)
    for member, network in zip(members, direct, strict=True):
        np.testing.assert_array_equal(member.predict(inputs), network.predict(inputs))
    with pytest.raises(ValueError, match="needs an 'mlp_kinematic' recipe without early stopping"):
        train_blender_kinematic(library, rows, TrainingRecipe(epochs=1, hidden=3), seed=0, members=2, log=None)
    with pytest.raises(ValueError, match="at least 2 members"):
        train_blender_kinematic(library, rows, recipe, seed=0, members=1, log=None)
