"""Train the encoder ensembles of the PoP of Amplification: the optimised blender's and the judges'.

Usage::

    python -m cogblocks.training.judges --seed 0 [--epochs 40]

Both ensembles are trained only on the training part of the shipped encoder's split (the
validation movements stay unseen) and are disjoint:

- the blender's ensemble: the shipped encoder plus ``blender_members − 1`` networks trained on the
  whole training part with torch seeds ``7000 + 10·seed + i`` (``encoder_ensemble.pt``);
- the judges: ``judges`` networks, each trained on the training part without one of ``judges``
  seeded folds (fold permutation seeded by ``seed``), torch seeds ``9000 + 10·seed + i``
  (``judges.pt``).

Everything is seeded and runs on one thread, so a seed reproduces the weights exactly. The
checkpoints hold float16 weights (about 25 kB per network).
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import torch

from cogblocks.amplification import EncoderNet
from cogblocks.amplification.judges import BLENDER_ENSEMBLE, JUDGE_ENSEMBLE, ensemble_checkpoint
from cogblocks.amplification.solution import library_fingerprint
from cogblocks.data.features import classifier_inputs
from cogblocks.data.reach import ReachLibrary
from cogblocks.training.encoder import EncoderConfig, train_network

__all__ = ["main", "train_blender_ensemble", "train_judges"]

WEIGHTS = Path(__file__).resolve().parent.parent / "data" / "weights"


def train_blender_ensemble(
    library: ReachLibrary,
    train: np.ndarray,
    config: EncoderConfig,
    seed: int,
    members: int,
    *,
    log: Callable[[str], None] | None = print,
) -> list[EncoderNet]:
    """``members`` networks trained on all of ``train`` with torch seeds ``7000 + 10·seed + i``."""
    inputs, fear = classifier_inputs(library)[train], library.fear[train]
    networks = []
    for i in range(members):
        started = time.perf_counter()
        networks.append(train_network(inputs, fear, config, 7000 + 10 * seed + i))
        if log is not None:
            log(f"blender ensemble member {i + 1}/{members} ({time.perf_counter() - started:.1f} s)")
    return networks


def train_judges(
    library: ReachLibrary,
    train: np.ndarray,
    config: EncoderConfig,
    seed: int,
    members: int = 5,
    *,
    log: Callable[[str], None] | None = print,
) -> list[EncoderNet]:
    """``members`` networks, each trained on ``train`` without one of ``members`` seeded folds."""
    inputs = classifier_inputs(library)
    folds = np.array_split(np.random.default_rng(seed).permutation(np.asarray(train)), members)
    networks = []
    for i, fold in enumerate(folds):
        started = time.perf_counter()
        rows = np.setdiff1d(train, fold)
        networks.append(train_network(inputs[rows], library.fear[rows], config, 9000 + 10 * seed + i))
        if log is not None:
            accuracy = float(np.mean((networks[-1].predict(inputs[fold]) > 0.5) == library.fear[fold]))
            log(
                f"judge {i + 1}/{members}: accuracy on its held-out fold {accuracy:.3f} "
                f"({time.perf_counter() - started:.1f} s)"
            )
    return networks


def main(argv: Sequence[str] | None = None) -> None:
    """Command-line entry point: train both ensembles on the shipped encoder's training part and save them."""
    from cogblocks.diagrams.amplification import amplification_setup

    parser = argparse.ArgumentParser(
        prog="python -m cogblocks.training.judges",
        description="Train the optimised blender's encoder ensemble and the independent judges' ensemble.",
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the folds and the weights (default 0)")
    parser.add_argument("--epochs", type=int, default=EncoderConfig.epochs, help="passes over the training data")
    parser.add_argument("--blender-members", type=int, default=2, help="networks the blender constrains (default 2)")
    parser.add_argument("--judges", type=int, default=5, help="networks of the judges' ensemble (default 5)")
    parser.add_argument("--out", type=Path, default=WEIGHTS, help=f"directory to write to (default {WEIGHTS})")
    args = parser.parse_args(argv)

    torch.set_num_threads(1)
    setup = amplification_setup(None, 1)
    config = EncoderConfig(epochs=args.epochs)
    meta = {"seed": args.seed, "library_sha256": library_fingerprint(setup.library), "epochs": args.epochs}
    extra = train_blender_ensemble(setup.library, setup.train, config, args.seed, args.blender_members - 1)
    judges = train_judges(setup.library, setup.train, config, args.seed, args.judges)
    args.out.mkdir(parents=True, exist_ok=True)
    torch.save(
        ensemble_checkpoint(extra, role="blender (with the shipped encoder)", **meta), args.out / BLENDER_ENSEMBLE
    )
    torch.save(ensemble_checkpoint(judges, role="judges", **meta), args.out / JUDGE_ENSEMBLE)
    print(f"saved {len(extra)} + 1 blender networks and {len(judges)} judges to {args.out}")


if __name__ == "__main__":
    main()
