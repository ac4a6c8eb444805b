"""How the encoder ensembles of the PoP of Amplification are trained, and how that recipe was chosen.

Usage::

    python -m cogblocks.training.recipe --seed 0   # cross-validates RECIPES on the training part
    python -m cogblocks.training.recipe --kinematic   # the kinematic judge's candidates, the same way

An ensemble (:func:`train_fold_ensemble`) holds ``members`` networks (:class:`EncoderNet` or another
candidate of :mod:`~cogblocks.training.architectures`): member ``i`` is trained on the given movements
without the ``i``-th of ``members`` seeded, stratified folds and stopped early on that fold (the epoch
of lowest loss on it is kept), with AdamW (weight decay).

The recipe is chosen only by cross-validation inside the training part of the shipped split
(:func:`cross_validate_recipe`): the training part is cut into ``folds`` stratified outer folds; for
each, an ensemble is trained on the others and its mean ε̂ decides the outer fold's movements with
the clipping rule (> 0.9 fear, < 0.1 no fear). The score is the mean over the two classes of the
share decided correctly minus the share decided wrongly: an undecided movement counts nothing, a
wrong decision as much against as a right one for. The held-out movements and the blended plans play
no part.
"""

from __future__ import annotations

import argparse
import copy
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass

import numpy as np
import torch
from torch import nn

from cogblocks.amplification.encoder import FEAR, NO_FEAR, clip_decision
from cogblocks.training.architectures import ARCHITECTURES, architecture_inputs, build_network
from cogblocks.training.encoder import train_epoch

__all__ = [
    "CHOSEN",
    "JUDGE_CHOSEN",
    "RECIPES",
    "TrainingRecipe",
    "clipped_shares",
    "cross_validate_kinematic",
    "cross_validate_recipe",
    "main",
    "stratified_folds",
    "train_fold_ensemble",
    "train_member",
]


@dataclass(frozen=True)
class TrainingRecipe:
    """Hyper-parameters of one ensemble member.

    Attributes
    ----------
    epochs : int
        Most passes over the training movements.
    batch_size : int
        Movements per AdamW step.
    learning_rate : float
        AdamW step size.
    weight_decay : float
        AdamW's decoupled weight decay.
    patience : int
        Epochs without a better ``stop_on`` figure on the stopping fold before training stops (0: never
        stop early, keep the last epoch).
    stop_on : {"loss", "clipped"}
        What early stopping watches on the stopping fold: its loss (lower is better) or its clipped
        score (the mean over the classes of the share decided correctly minus the share decided
        wrongly; higher is better, ties to the later epoch).
    hidden : int
        Hidden ReLU units.
    dropout : float
        Dropout on the hidden units during training.
    architecture : str
        The network and its inputs (:data:`~cogblocks.training.architectures.ARCHITECTURES`); for
        ``"cnn"`` ``hidden`` is the number of filters, for ``"gru"`` the state size.
    """

    epochs: int = 40
    batch_size: int = 20
    learning_rate: float = 1e-3
    weight_decay: float = 0.0
    patience: int = 0
    stop_on: str = "loss"
    hidden: int = 200
    dropout: float = 0.2
    architecture: str = "mlp"

    def __post_init__(self) -> None:
        if self.stop_on not in ("loss", "clipped"):
            raise ValueError(f"TrainingRecipe: stop_on must be 'loss' or 'clipped', got {self.stop_on!r}")
        if self.architecture not in ARCHITECTURES:
            raise ValueError(f"TrainingRecipe: architecture must be one of {ARCHITECTURES}, got {self.architecture!r}")


#: The recipes compared by ``python -m cogblocks.training.recipe`` (``"baseline"`` is the encoder's own).
RECIPES = {
    "baseline": TrainingRecipe(),
    "long": TrainingRecipe(epochs=200, batch_size=32),
    "long_stop": TrainingRecipe(epochs=200, batch_size=32, patience=30),
    "long_stop_wd": TrainingRecipe(epochs=200, batch_size=32, weight_decay=1e-2, patience=30),
    "long_stop_fast": TrainingRecipe(epochs=200, batch_size=32, learning_rate=3e-3, weight_decay=1e-2, patience=30),
    "long_stop_small": TrainingRecipe(epochs=200, batch_size=32, weight_decay=1e-2, patience=30, hidden=64),
    "longer_fast": TrainingRecipe(epochs=300, batch_size=32, learning_rate=3e-3, weight_decay=1e-2),
    "long_nodrop": TrainingRecipe(epochs=200, batch_size=32, weight_decay=1e-2, dropout=0.0),
    "long_drop5": TrainingRecipe(epochs=200, batch_size=32, weight_decay=1e-2, dropout=0.5),
    "longest_fast": TrainingRecipe(epochs=600, batch_size=32, learning_rate=3e-3, weight_decay=1e-2),
    "longer_fast_wide": TrainingRecipe(epochs=300, batch_size=32, learning_rate=3e-3, weight_decay=1e-2, hidden=400),
    "stop_clipped": TrainingRecipe(
        epochs=300, batch_size=32, learning_rate=3e-3, weight_decay=1e-2, patience=60, stop_on="clipped"
    ),
    # architectures and inputs (cogblocks.training.architectures), longest_fast's optimiser settings
    **{
        name: TrainingRecipe(
            epochs=600, batch_size=32, learning_rate=3e-3, weight_decay=1e-2, hidden=hidden, architecture=arch
        )
        for name, arch, hidden in (
            ("cnn", "cnn", 16),
            ("mlp_kinematic", "mlp_kinematic", 200),
            ("mlp_shape_kinematic", "mlp_shape_kinematic", 200),
        )
    },
    "gru": TrainingRecipe(
        epochs=300, batch_size=32, learning_rate=3e-3, weight_decay=1e-2, hidden=32, architecture="gru"
    ),
}


#: The recipe of the shipped ensembles: the best cross-validation score of :data:`RECIPES`
#: (``python -m cogblocks.training.recipe --seed 0``; docs/validation/amplification.md has the table).
CHOSEN = "longest_fast"

#: The recipe of the shipped judges: the best cross-validation score of :data:`RECIPES` (architectures
#: included). Its networks take the kinematic features too: the blender's profile ensemble keeps :data:`CHOSEN`,
#: the best of the profile-only candidates (``mlp``, ``cnn``), and its kinematic members (linearised solver
#: only) are bagged networks of this recipe (:func:`cogblocks.training.judges.train_blender_kinematic`).
JUDGE_CHOSEN = "mlp_kinematic"


def stratified_folds(labels: np.ndarray, rows: np.ndarray, folds: int, seed: int) -> list[np.ndarray]:
    """``rows`` cut into ``folds`` disjoint folds, each class spread evenly, seeded; each fold sorted."""
    rng = np.random.default_rng(seed)
    parts: list[list[np.ndarray]] = [[] for _ in range(folds)]
    for label in (False, True):
        members = rng.permutation(rows[np.asarray(labels)[rows] == label])
        for i, chunk in enumerate(np.array_split(members, folds)):
            parts[(i + label * (folds // 2)) % folds].append(chunk)  # offset: the small folds of each class differ
    return [np.sort(np.concatenate(p)) for p in parts]


def train_member(
    inputs: np.ndarray,
    labels: np.ndarray,
    recipe: TrainingRecipe,
    seed: int,
    stop: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[nn.Module, int]:
    """One network trained on ``inputs`` (n, 60) and boolean ``labels``; with ``stop`` (inputs, labels),
    stopped early on their loss (see :class:`TrainingRecipe`). Returns the network and the epoch kept."""
    torch.manual_seed(seed)
    generator = torch.Generator().manual_seed(seed)
    network = build_network(recipe.architecture, inputs.shape[1], recipe.hidden, recipe.dropout)
    network.set_normalisation(inputs)
    optimiser = torch.optim.AdamW(network.parameters(), lr=recipe.learning_rate, weight_decay=recipe.weight_decay)
    x = torch.as_tensor(inputs, dtype=torch.float32)
    y = torch.as_tensor(labels, dtype=torch.float32)
    loss_fn = nn.BCELoss()
    early = stop is not None and recipe.patience > 0
    if early:
        x_stop = torch.as_tensor(stop[0], dtype=torch.float32)
        y_stop = torch.as_tensor(stop[1], dtype=torch.float32)
    best_loss, best_state, best_epoch = np.inf, None, recipe.epochs
    for epoch in range(1, recipe.epochs + 1):
        train_epoch(network, optimiser, loss_fn, x, y, recipe.batch_size, generator)
        if early:
            network.eval()
            with torch.no_grad():
                eps = network(x_stop)
                held = float(loss_fn(eps, y_stop))
            if recipe.stop_on == "clipped":  # minimised: minus the score, the later epoch on a tie
                shares = clipped_shares(eps.double().numpy(), stop[1]).values()
                held = -float(np.mean([s["correct"] - s["wrong"] for s in shares])) - 1e-9 * epoch
            if held < best_loss:
                best_loss, best_state, best_epoch = held, copy.deepcopy(network.state_dict()), epoch
            elif epoch - best_epoch >= recipe.patience:
                break
    if best_state is not None:
        network.load_state_dict(best_state)
    network.eval()
    return network, best_epoch


def train_fold_ensemble(
    inputs: np.ndarray,
    labels: np.ndarray,
    rows: np.ndarray,
    recipe: TrainingRecipe,
    *,
    fold_seed: int,
    torch_seed: int,
    members: int = 5,
    log: Callable[[str], None] | None = None,
    name: str = "member",
) -> list[nn.Module]:
    """``members`` networks: member ``i`` trained on ``rows`` without fold ``i`` and stopped early on it.

    The folds are :func:`stratified_folds` of ``rows`` (seed ``fold_seed``); member ``i`` has torch seed
    ``torch_seed + i``. ``inputs`` and ``labels`` cover every movement; only ``rows`` are used.
    """
    labels = np.asarray(labels, dtype=bool)
    networks = []
    for i, fold in enumerate(stratified_folds(labels, np.asarray(rows), members, fold_seed)):
        started = time.perf_counter()
        train = np.setdiff1d(rows, fold)
        network, epoch = train_member(
            inputs[train], labels[train], recipe, torch_seed + i, stop=(inputs[fold], labels[fold])
        )
        networks.append(network)
        if log is not None:
            accuracy = float(np.mean((network.predict(inputs[fold]) > 0.5) == labels[fold]))
            log(
                f"{name} {i + 1}/{members}: epoch {epoch} kept, accuracy on its left-out fold {accuracy:.3f} "
                f"({time.perf_counter() - started:.1f} s)"
            )
    return networks


def clipped_shares(eps_hat: np.ndarray, fear: np.ndarray) -> dict[str, dict[str, float]]:
    """Per class (``"fear"``, ``"no_fear"``): the share decided correctly and wrongly by the clipping rule."""
    decision, fear = clip_decision(eps_hat), np.asarray(fear, dtype=bool)
    shares = {}
    for name, label in (("fear", FEAR), ("no_fear", NO_FEAR)):
        own = decision[fear == bool(label)]
        shares[name] = {
            "n": int(len(own)),
            "correct": float(np.mean(own == label)) if len(own) else float("nan"),
            "wrong": float(np.mean(own == 1 - label)) if len(own) else float("nan"),
        }
    return shares


def cross_validate_recipe(
    inputs: np.ndarray,
    labels: np.ndarray,
    rows: np.ndarray,
    recipe: TrainingRecipe,
    seed: int = 0,
    *,
    folds: int = 5,
    members: int = 5,
) -> dict[str, float]:
    """The clipped ensemble's out-of-fold shares on ``rows`` (see the module docstring) and its ``score``."""
    labels = np.asarray(labels, dtype=bool)
    eps = np.full(len(labels), np.nan)
    for k, outer in enumerate(stratified_folds(labels, np.asarray(rows), folds, seed)):
        inner = np.setdiff1d(rows, outer)
        ensemble = train_fold_ensemble(
            inputs, labels, inner, recipe, fold_seed=seed + 1 + k, torch_seed=20000 + 100 * k, members=members
        )
        eps[outer] = np.mean([n.predict(inputs[outer]) for n in ensemble], axis=0)
    shares = clipped_shares(eps[rows], labels[rows])
    score = float(np.mean([s["correct"] - s["wrong"] for s in shares.values()]))
    return {
        **{f"{c}_{k}": v for c, s in shares.items() for k, v in s.items() if k != "n"},
        "accuracy": float(np.mean((eps[rows] > 0.5) == labels[rows])),
        "score": score,
    }


def cross_validate_kinematic(features: np.ndarray, labels: np.ndarray, seed: int = 0) -> dict[str, dict[str, float]]:
    """5-fold stratified cross-validation of kinematic classifiers (scikit-learn) decided at probability 0.5.

    The candidates: the :class:`~cogblocks.amplification.judges.KinematicJudge`'s logistic regression
    (C = 1 and 0.1, standardised features) and gradient boosting of depth 1–3. Per model: the share of
    each class decided correctly and their mean (``balanced``).
    """
    from sklearn.ensemble import GradientBoostingClassifier
    from sklearn.linear_model import LogisticRegression
    from sklearn.model_selection import StratifiedKFold, cross_val_predict
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    models = {
        "logistic C=1": make_pipeline(StandardScaler(), LogisticRegression(C=1.0, max_iter=1000)),
        "logistic C=0.1": make_pipeline(StandardScaler(), LogisticRegression(C=0.1, max_iter=1000)),
        "boosting depth 1, 300 trees": GradientBoostingClassifier(max_depth=1, n_estimators=300, random_state=seed),
        "boosting depth 2, 100 trees": GradientBoostingClassifier(max_depth=2, random_state=seed),
        "boosting depth 3, 100 trees": GradientBoostingClassifier(max_depth=3, random_state=seed),
    }
    labels = np.asarray(labels, dtype=bool)
    folds = StratifiedKFold(5, shuffle=True, random_state=seed)
    rows = {}
    for name, model in models.items():
        fear = cross_val_predict(model, features, labels, cv=folds, method="predict_proba")[:, 1] > 0.5
        shares = {"fear": float(np.mean(fear[labels])), "no_fear": float(np.mean(~fear[~labels]))}
        rows[name] = {**shares, "balanced": (shares["fear"] + shares["no_fear"]) / 2}
    return rows


def main(argv: Sequence[str] | None = None) -> None:
    """Command-line entry point: cross-validate every recipe of :data:`RECIPES` on the shipped training part."""
    from cogblocks.amplification.judges import kinematic_features
    from cogblocks.data.features import classifier_inputs
    from cogblocks.diagrams.amplification_setup import amplification_setup

    parser = argparse.ArgumentParser(prog="python -m cogblocks.training.recipe", description=__doc__)
    parser.add_argument("--seed", type=int, default=0, help="seed of the outer and inner folds (default 0)")
    parser.add_argument("--only", nargs="*", choices=sorted(RECIPES), help="recipes to compare (default all)")
    parser.add_argument("--kinematic", action="store_true", help="compare the kinematic classifiers instead")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    setup = amplification_setup(None, 1)
    profile, labels = classifier_inputs(setup.library), setup.library.fear
    if args.kinematic:
        features = kinematic_features(setup.library.velocity[setup.train], setup.library.dt)
        for name, row in cross_validate_kinematic(features, labels[setup.train], args.seed).items():
            print(f"{name}: " + " ".join(f"{k} {v:.3f}" for k, v in row.items()))
        return
    for name in args.only or RECIPES:
        started = time.perf_counter()
        recipe = RECIPES[name]
        inputs = architecture_inputs(recipe.architecture, profile, setup.library.velocity, setup.library.dt)
        row = cross_validate_recipe(inputs, labels, setup.train, recipe, args.seed)
        cells = " ".join(f"{k} {v:.3f}" for k, v in row.items())
        print(f"{name}: {cells} ({time.perf_counter() - started:.0f} s) {asdict(RECIPES[name])}", flush=True)


if __name__ == "__main__":
    main()
