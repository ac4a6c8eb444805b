"""Train the encoder ensembles of the PoP of Amplification: the optimised blender's and the judges'.

Usage::

    python -m cogblocks.training.judges --seed 0 [--recipe NAME] [--judge-recipe NAME] [--kinematic-members N]
        [--only blender judges kinematic]

The blender's ensemble is trained with the recipe :data:`~cogblocks.training.recipe.CHOSEN`, the judges
with :data:`~cogblocks.training.recipe.JUDGE_CHOSEN` (both chosen by cross-validation inside the training
part, ``python -m cogblocks.training.recipe``; the judges' networks also take kinematic features, which
only the blender's linearised solver constrains), only on the training part of the shipped encoder's split
(the validation movements stay unseen), and are disjoint (other folds, other seeds):

- the blender's ensemble: ``blender_members`` networks (:func:`train_blender_ensemble`), torch seeds
  ``7000 + 10·seed + i`` (``encoder_ensemble.pt``);
- the blender's kinematic members: ``kinematic_members`` networks of the judges' recipe (the profile and
  the kinematic features, which the linearised solver constrains through their subgradients), each on the
  training part without one of ``kinematic_members`` folds (:func:`train_blender_kinematic`, fold seed
  ``seed + 1000``), torch seeds ``7100 + 10·seed + i`` (``encoder_ensemble_kinematic.pt``);
- the judges: ``judges`` networks, each trained on the training part without one of ``judges``
  seeded, stratified folds (:func:`~cogblocks.training.recipe.train_fold_ensemble`, fold seed
  ``seed``), torch seeds ``9000 + 10·seed + i`` (``judges.pt``).

Everything is seeded and runs on one thread, so a seed reproduces the weights exactly. The
checkpoints hold float16 weights (about 25 kB per network).
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch

from cogblocks.amplification import EncoderNet
from cogblocks.amplification.judges import (
    BLENDER_ENSEMBLE,
    BLENDER_KINEMATIC_ENSEMBLE,
    JUDGE_ENSEMBLE,
    ensemble_checkpoint,
)
from cogblocks.amplification.solution import library_fingerprint
from cogblocks.data.features import classifier_inputs
from cogblocks.data.reach import ReachLibrary
from cogblocks.training.architectures import architecture_inputs, as_encoder_net
from cogblocks.training.recipe import CHOSEN, JUDGE_CHOSEN, RECIPES, TrainingRecipe, train_fold_ensemble, train_member

__all__ = ["main", "train_blender_ensemble", "train_blender_kinematic", "train_judges"]

WEIGHTS = Path(__file__).resolve().parent.parent / "data" / "weights"
#: Networks of the blender's ensemble (``encoder_ensemble.pt``); the shipped encoder is not one of them.
BLENDER_MEMBERS = 2
#: Kinematic networks of the blender (``encoder_ensemble_kinematic.pt``).
BLENDER_KINEMATIC_MEMBERS = 4
#: Fold seeds of the blender's ensemble are offset from the judges' so that their folds differ.
BLENDER_FOLD_OFFSET = 1000
#: The ensembles ``--only`` can name.
PARTS = ("blender", "kinematic", "judges")


def train_blender_ensemble(
    library: ReachLibrary,
    train: np.ndarray,
    recipe: TrainingRecipe,
    seed: int,
    members: int,
    *,
    log: Callable[[str], None] | None = print,
) -> list[EncoderNet]:
    """``members`` networks with torch seeds ``7000 + 10·seed + i``.

    Without early stopping in ``recipe`` each is trained on all of ``train``; with it, each on
    ``train`` without one of ``max(members, 2)`` folds (fold seed ``seed + 1000``: not the judges'),
    stopped early on that fold.
    """
    inputs, fear = classifier_inputs(library), library.fear
    if recipe.patience > 0:
        folds = max(members, 2)
        networks = train_fold_ensemble(
            inputs, fear, np.asarray(train), recipe, fold_seed=seed + BLENDER_FOLD_OFFSET,
            torch_seed=7000 + 10 * seed, members=folds, log=log, name="blender ensemble member",
        )  # fmt: skip
        return [as_encoder_net(n) for n in networks[:members]]
    networks = []
    for i in range(members):
        started = time.perf_counter()
        networks.append(as_encoder_net(train_member(inputs[train], fear[train], recipe, 7000 + 10 * seed + i)[0]))
        if log is not None:
            log(f"blender ensemble member {i + 1}/{members} ({time.perf_counter() - started:.1f} s)")
    return networks


def train_blender_kinematic(
    library: ReachLibrary,
    train: np.ndarray,
    recipe: TrainingRecipe,
    seed: int,
    members: int,
    *,
    log: Callable[[str], None] | None = print,
) -> list[EncoderNet]:
    """``members`` (≥ 2) networks of a recipe with kinematic inputs, each trained on ``train`` without one of
    ``members`` seeded, stratified folds (fold seed ``seed + 1000``: not the judges'), torch seeds
    ``7100 + 10·seed + i``.

    Bagged like the judges (whose seeds, 9000 + …, and folds they do not share): on the inner split such members
    made the plans convince the judges more often than members trained on the whole part did
    (docs/validation/amplification.md). The recipe's architecture must be ``"mlp_kinematic"``, the
    one the blender can constrain, without early stopping.
    """
    if recipe.architecture != "mlp_kinematic" or recipe.patience > 0 or members < 2:
        raise ValueError(
            "train_blender_kinematic: needs an 'mlp_kinematic' recipe without early stopping and at least 2 members, "
            f"got architecture {recipe.architecture!r}, patience {recipe.patience}, {members} members"
        )
    inputs = architecture_inputs(recipe.architecture, classifier_inputs(library), library.velocity, library.dt)
    networks = train_fold_ensemble(
        inputs, library.fear, np.asarray(train), recipe, fold_seed=seed + BLENDER_FOLD_OFFSET,
        torch_seed=7100 + 10 * seed, members=members, log=log, name="blender kinematic member",
    )  # fmt: skip
    return [as_encoder_net(n, judge=True) for n in networks]


def train_judges(
    library: ReachLibrary,
    train: np.ndarray,
    recipe: TrainingRecipe,
    seed: int,
    members: int = 5,
    *,
    log: Callable[[str], None] | None = print,
) -> list[EncoderNet]:
    """``members`` networks, each trained on ``train`` without one of ``members`` seeded, stratified folds."""
    inputs = architecture_inputs(recipe.architecture, classifier_inputs(library), library.velocity, library.dt)
    networks = train_fold_ensemble(
        inputs, library.fear, np.asarray(train), recipe, fold_seed=seed,
        torch_seed=9000 + 10 * seed, members=members, log=log, name="judge",
    )  # fmt: skip
    return [as_encoder_net(n, judge=True) for n in networks]


def main(argv: Sequence[str] | None = None) -> None:
    """Command-line entry point: train both ensembles on the shipped encoder's training part and save them."""
    from cogblocks.diagrams.amplification import amplification_setup

    parser = argparse.ArgumentParser(
        prog="python -m cogblocks.training.judges",
        description="Train the optimised blender's encoder ensemble and the independent judges' ensemble.",
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the folds and the weights (default 0)")
    parser.add_argument(
        "--recipe", default=CHOSEN, choices=sorted(RECIPES), help=f"the blender ensemble's recipe (default {CHOSEN})"
    )
    parser.add_argument(
        "--judge-recipe", default=JUDGE_CHOSEN, choices=sorted(RECIPES),
        help=f"the judges' recipe (default {JUDGE_CHOSEN})",
    )  # fmt: skip
    parser.add_argument(
        "--blender-members", type=int, default=BLENDER_MEMBERS,
        help=f"networks the blender constrains (default {BLENDER_MEMBERS})",
    )  # fmt: skip
    parser.add_argument(
        "--kinematic-members", type=int, default=BLENDER_KINEMATIC_MEMBERS,
        help=f"kinematic networks the blender constrains, recipe --judge-recipe (default {BLENDER_KINEMATIC_MEMBERS})",
    )  # fmt: skip
    parser.add_argument("--judges", type=int, default=5, help="networks of the judges' ensemble (default 5)")
    parser.add_argument(
        "--only", nargs="+", choices=PARTS, default=list(PARTS),
        help="train and save only these ensembles (default all; each is seeded on its own)",
    )  # fmt: skip
    parser.add_argument("--out", type=Path, default=WEIGHTS, help=f"directory to write to (default {WEIGHTS})")
    args = parser.parse_args(argv)

    torch.set_num_threads(1)
    setup = amplification_setup(None, 1)
    fingerprint = library_fingerprint(setup.library)

    def meta(name: str) -> dict:
        recipe = RECIPES[name]
        return {"seed": args.seed, "library_sha256": fingerprint, "recipe": name, "architecture": recipe.architecture,
                **{f"recipe_{k}": v for k, v in asdict(recipe).items()}}  # fmt: skip

    args.out.mkdir(parents=True, exist_ok=True)
    library, train = setup.library, setup.train
    if "blender" in args.only:
        blender = train_blender_ensemble(library, train, RECIPES[args.recipe], args.seed, args.blender_members)
        torch.save(ensemble_checkpoint(blender, role="blender", **meta(args.recipe)), args.out / BLENDER_ENSEMBLE)
        print(f"saved {len(blender)} blender networks to {args.out / BLENDER_ENSEMBLE}")
    if "kinematic" in args.only:
        kinematic = train_blender_kinematic(
            library, train, RECIPES[args.judge_recipe], args.seed, args.kinematic_members
        )  # fmt: skip
        checkpoint = ensemble_checkpoint(kinematic, role="blender", **meta(args.judge_recipe))
        torch.save(checkpoint, args.out / BLENDER_KINEMATIC_ENSEMBLE)
        print(f"saved {len(kinematic)} kinematic blender networks to {args.out / BLENDER_KINEMATIC_ENSEMBLE}")
    if "judges" in args.only:
        judges = train_judges(library, train, RECIPES[args.judge_recipe], args.seed, args.judges)
        torch.save(ensemble_checkpoint(judges, role="judges", **meta(args.judge_recipe)), args.out / JUDGE_ENSEMBLE)
        print(f"saved {len(judges)} judges to {args.out / JUDGE_ENSEMBLE}")


if __name__ == "__main__":
    main()
