"""The training recipe of the encoder ensembles (judges and blender) and its cross-validation."""

from dataclasses import replace

import numpy as np
import pytest
import torch
from torch import nn

from cogblocks.amplification.encoder import EncoderNet, clip_decision
from cogblocks.amplification.judges import ensemble_checkpoint, load_ensemble
from cogblocks.data.features import classifier_inputs
from cogblocks.data.reach import generate_reach_library
from cogblocks.training.judges import train_blender_ensemble, train_judges
from cogblocks.training.recipe import (
    CHOSEN,
    JUDGE_CHOSEN,
    RECIPES,
    TrainingRecipe,
    clipped_shares,
    cross_validate_kinematic,
    cross_validate_recipe,
    stratified_folds,
    train_member,
)

torch.set_num_threads(1)
TINY = TrainingRecipe(epochs=3, batch_size=16, hidden=8)


@pytest.fixture(scope="module")
def small():
    library = generate_reach_library(3, n_subjects=2, n_fear=15, n_no_fear=15)
    return library, classifier_inputs(library)


def test_stratified_folds_partition_the_rows_class_by_class():
    labels = np.r_[np.zeros(23, bool), np.ones(17, bool)]
    rows = np.arange(3, 40)
    folds = stratified_folds(labels, rows, 5, seed=4)
    assert np.array_equal(np.sort(np.concatenate(folds)), rows)
    for label in (False, True):
        counts = [int(np.sum(labels[f] == label)) for f in folds]
        assert max(counts) - min(counts) <= 1
    assert all(np.array_equal(a, b) for a, b in zip(folds, stratified_folds(labels, rows, 5, seed=4), strict=True))
    assert not all(np.array_equal(a, b) for a, b in zip(folds, stratified_folds(labels, rows, 5, seed=5), strict=True))


def test_member_is_seeded_and_early_stopping_keeps_the_best_epoch(small):
    library, inputs = small
    train, stop = np.arange(0, 30, 2), np.arange(1, 30, 2)
    recipe = TrainingRecipe(epochs=12, batch_size=8, hidden=8, patience=12)
    a, epoch = train_member(inputs[train], library.fear[train], recipe, 3, stop=(inputs[stop], library.fear[stop]))
    b, _ = train_member(inputs[train], library.fear[train], recipe, 3, stop=(inputs[stop], library.fear[stop]))
    assert torch.equal(a.hidden.weight, b.hidden.weight)
    assert 1 <= epoch <= 12
    # the kept network is the one of that epoch: training for exactly that many epochs gives the same weights
    plain, _ = train_member(inputs[train], library.fear[train], replace(recipe, epochs=epoch, patience=0), 3)
    torch.testing.assert_close(a.state_dict(), plain.state_dict())
    # and no epoch has a lower loss on the stopping fold
    loss = nn.BCELoss()
    x, y = torch.as_tensor(inputs[stop], dtype=torch.float32), torch.as_tensor(library.fear[stop], dtype=torch.float32)
    with torch.no_grad():
        best = float(loss(a(x), y))
    for n in range(1, 13):
        other, _ = train_member(inputs[train], library.fear[train], replace(recipe, epochs=n, patience=0), 3)
        with torch.no_grad():
            assert best <= float(loss(other(x), y)) + 1e-6


def test_clipped_shares_count_each_class():
    eps = np.array([0.95, 0.5, 0.05, 0.99, 0.02, 0.2])
    fear = np.array([True, True, True, False, False, False])
    shares = clipped_shares(eps, fear)
    assert shares["fear"] == {"n": 3, "correct": pytest.approx(1 / 3), "wrong": pytest.approx(1 / 3)}
    assert shares["no_fear"] == {"n": 3, "correct": pytest.approx(1 / 3), "wrong": pytest.approx(1 / 3)}
    decision = clip_decision(eps)
    assert shares["fear"]["correct"] == pytest.approx(np.mean(decision[fear] == 1))


def test_cross_validation_scores_out_of_fold(small):
    library, inputs = small
    rows = np.arange(len(library))
    row = cross_validate_recipe(inputs, library.fear, rows, TINY, seed=1, folds=3, members=2)
    assert row["score"] == pytest.approx(
        np.mean([row["fear_correct"] - row["fear_wrong"], row["no_fear_correct"] - row["no_fear_wrong"]])
    )
    assert 0.0 <= row["accuracy"] <= 1.0
    assert row == cross_validate_recipe(inputs, library.fear, rows, TINY, seed=1, folds=3, members=2)


def test_judges_and_blender_ensemble_interface(small, tmp_path):
    library, _ = small
    train = np.arange(24)
    lines = []
    judges = train_judges(library, train, TINY, seed=0, members=3, log=lines.append)
    again = train_judges(library, train, TINY, seed=0, members=3, log=None)
    blender = train_blender_ensemble(library, train, TINY, seed=0, members=2, log=None)
    assert len(judges) == 3 and len(blender) == 2 and all(isinstance(n, EncoderNet) for n in judges + blender)
    assert len(lines) == 3 and lines[0].startswith("judge 1/3")
    assert torch.equal(judges[0].hidden.weight, again[0].hidden.weight)
    weights = [n.hidden.weight for n in judges + blender]
    assert all(not torch.equal(weights[i], weights[j]) for i in range(len(weights)) for j in range(i))
    torch.save(ensemble_checkpoint(judges, role="judges", recipe="tiny"), tmp_path / "judges.pt")
    loaded = load_ensemble(tmp_path / "judges.pt")
    x = classifier_inputs(library)[24:]
    for net, back in zip(judges, loaded, strict=True):
        np.testing.assert_allclose(back.predict(x), net.predict(x), atol=5e-3)  # float16 weights
    assert loaded[0].checkpoint["recipe"] == "tiny" and loaded[0].hidden.out_features == 8
    # with early stopping, the blender's members are stopped on folds other than the judges'
    stopped = train_blender_ensemble(library, train, replace(TINY, patience=2), 0, 1, log=None)
    assert len(stopped) == 1


def test_the_chosen_recipe_is_one_of_the_compared():
    assert CHOSEN in RECIPES and JUDGE_CHOSEN in RECIPES and RECIPES["baseline"] == TrainingRecipe()
    assert RECIPES[CHOSEN].architecture in ("mlp", "cnn")  # the blender can constrain only these
    shipped = load_ensemble("judges.pt")
    assert shipped[0].checkpoint["recipe"] == JUDGE_CHOSEN and len(shipped) == 5
    assert shipped[0].checkpoint["architecture"] == RECIPES[JUDGE_CHOSEN].architecture
    assert load_ensemble("encoder_ensemble.pt")[0].checkpoint["recipe"] == CHOSEN


def test_kinematic_candidates_cross_validated():
    rng = np.random.default_rng(0)
    labels = np.arange(40) % 2 == 0
    separable = np.c_[labels + 0.05 * rng.normal(size=40), rng.normal(size=40)]
    rows = cross_validate_kinematic(separable, labels)
    assert len(rows) == 5 and all(row == {"fear": 1.0, "no_fear": 1.0, "balanced": 1.0} for row in rows.values())
    noise = cross_validate_kinematic(rng.normal(size=(40, 2)), labels)
    for row in noise.values():
        assert row["balanced"] == pytest.approx((row["fear"] + row["no_fear"]) / 2) and row["balanced"] < 0.9
