"""Train the encoding classifier ε̂ of the PoP of Amplification, with 5-fold cross-validation.

Usage::

    python -m cogblocks.training.encoder --seed 0 [--epochs N] [--out encoder.pt]

The checkpoint goes to ``--out``, by default ``encoder.pt`` in the working directory: the weights
shipped with the package (``cogblocks/data/weights/encoder.pt``) are replaced only when ``--out``
names them.

As in the appendix paper (section V-B): the inputs are the library's velocities restricted to each
movement's duration and resampled to 20 points per axis (60 inputs); the network is
:class:`~cogblocks.amplification.EncoderNet` (200 ReLU units, dropout, sigmoid), trained with Adam
(learning rate 1e-3) on the binary cross-entropy. Five random stratified 70/30 splits of the
synthetic library (``ReachLibrary.split`` with seeds ``5·seed … 5·seed + 4``) each train one
network. Each is validated with the clipping rule: per class, the accuracy among the decided
signals (ε̂ > 0.9 or ε̂ < 0.1) and the share misclassified. The network with the best plain
validation accuracy (threshold 0.5) is saved, with its split seed and the cross-validation table,
so that the amplification results can be computed on movements it has never seen.

Everything is seeded and runs on one thread, so a seed reproduces the weights exactly.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn

from cogblocks.amplification import EncoderNet
from cogblocks.amplification.encoder import FEAR, NO_FEAR, clip_decision
from cogblocks.amplification.solution import library_fingerprint, library_summary
from cogblocks.data.features import classifier_inputs
from cogblocks.data.reach import ReachLibrary, generate_reach_library

__all__ = ["EncoderConfig", "FoldResult", "class_report", "cross_validate", "main", "train_epoch", "train_network"]

DEFAULT_OUT = Path("encoder.pt")  # in the working directory, never the shipped weights by default
SHIPPED = Path(__file__).resolve().parent.parent / "data" / "weights" / "encoder.pt"


@dataclass(frozen=True)
class EncoderConfig:
    """Hyper-parameters of the cross-validation.

    Attributes
    ----------
    epochs : int
        Passes over the training part of each split.
    batch_size : int
        Movements per gradient step.
    learning_rate : float
        Adam step size.
    hidden : int
        Hidden units.
    dropout : float
        Dropout probability on the hidden units.
    folds : int
        Number of random splits.
    val_fraction : float
        Share of each class held out for validation.
    library_seed : int
        Seed of :func:`~cogblocks.data.reach.generate_reach_library`.
    """

    epochs: int = 40
    batch_size: int = 20
    learning_rate: float = 1e-3
    hidden: int = 200
    dropout: float = 0.2
    folds: int = 5
    val_fraction: float = 0.3
    library_seed: int = 0


@dataclass
class FoldResult:
    """One split of the cross-validation: its network and validation figures."""

    split_seed: int
    network: EncoderNet
    accuracy: float
    report: dict[str, dict[str, float]]


def class_report(eps_hat: np.ndarray, fear: np.ndarray) -> dict[str, dict[str, float]]:
    """Validation figures with the clipping rule, per class.

    Returns
    -------
    dict
        ``{"fear": {...}, "no_fear": {...}}`` with ``n``, ``decided`` (share of the class with
        a decision), ``accuracy`` (correct among the decided), ``misclassified`` (share of the
        class decided as the other class) and ``undecided``.
    """
    decision = clip_decision(eps_hat)
    report = {}
    for name, label in (("fear", FEAR), ("no_fear", NO_FEAR)):
        members = decision[fear == bool(label)]
        decided = members >= 0
        correct = int(np.sum(members == label))
        n = len(members)
        report[name] = {
            "n": n,
            "decided": float(decided.mean()) if n else float("nan"),
            "accuracy": correct / int(decided.sum()) if decided.any() else float("nan"),
            "misclassified": float(np.mean(members == 1 - label)) if n else float("nan"),
            "undecided": float(np.mean(~decided)) if n else float("nan"),
        }
    return report


def train_network(inputs: np.ndarray, labels: np.ndarray, config: EncoderConfig, seed: int) -> EncoderNet:
    """Train one :class:`EncoderNet` on ``inputs`` (n, 60) and boolean ``labels`` (n,)."""
    torch.manual_seed(seed)
    generator = torch.Generator().manual_seed(seed)
    network = EncoderNet(n_inputs=inputs.shape[1], hidden=config.hidden, dropout=config.dropout)
    network.set_normalisation(inputs)
    optimiser = torch.optim.Adam(network.parameters(), lr=config.learning_rate)
    x = torch.as_tensor(inputs, dtype=torch.float32)
    y = torch.as_tensor(labels, dtype=torch.float32)
    loss_fn = nn.BCELoss()
    for _ in range(config.epochs):
        train_epoch(network, optimiser, loss_fn, x, y, config.batch_size, generator)
    network.eval()
    return network


def train_epoch(
    network: nn.Module,
    optimiser: torch.optim.Optimizer,
    loss_fn: nn.Module,
    x: torch.Tensor,
    y: torch.Tensor,
    batch_size: int,
    generator: torch.Generator,
) -> None:
    """One pass over ``x``, ``y`` in minibatches of ``batch_size``, shuffled by ``generator``, in training mode."""
    network.train()
    order = torch.randperm(len(x), generator=generator)
    for start in range(0, len(x), batch_size):
        batch = order[start : start + batch_size]
        loss = loss_fn(network(x[batch]), y[batch])
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()


def cross_validate(
    config: EncoderConfig,
    seed: int,
    *,
    library: ReachLibrary | None = None,
    log: Callable[[str], None] | None = print,
) -> list[FoldResult]:
    """Train and validate one network per split; see the module docstring.

    Parameters
    ----------
    config : EncoderConfig
        Hyper-parameters.
    seed : int
        Split ``f`` uses split seed ``folds·seed + f`` and torch seed ``1000·seed + f``.
    library : ReachLibrary, optional
        The data; ``generate_reach_library(config.library_seed)`` by default.
    log : callable, optional
        Receives one line per split; ``None`` is silent.
    """
    library = generate_reach_library(config.library_seed) if library is None else library
    inputs = classifier_inputs(library)
    results = []
    for fold in range(config.folds):
        split_seed = config.folds * seed + fold
        train, val = library.split(config.val_fraction, split_seed)
        started = time.perf_counter()
        network = train_network(inputs[train], library.fear[train], config, 1000 * seed + fold)
        eps = network.predict(inputs[val])
        accuracy = float(np.mean((eps > 0.5) == library.fear[val]))
        report = class_report(eps, library.fear[val])
        results.append(FoldResult(split_seed, network, accuracy, report))
        if log is not None:
            log(
                f"split {fold} (seed {split_seed}): accuracy {accuracy:.3f}; "
                + "; ".join(
                    f"{name} decided-accuracy {r['accuracy']:.3f} misclassified {r['misclassified']:.3f} "
                    f"undecided {r['undecided']:.3f}"
                    for name, r in report.items()
                )
                + f"  ({time.perf_counter() - started:.1f} s)"
            )
    return results


def format_table(results: Sequence[FoldResult]) -> str:
    """The cross-validation as a Markdown table (percentages), with the mean row and the paper's."""
    lines = [
        "| split | accuracy | fear: accuracy (decided) | fear: misclassified | fear: undecided "
        "| no fear: accuracy (decided) | no fear: misclassified | no fear: undecided |",
        "|---|---|---|---|---|---|---|---|",
    ]

    def row(label: str, acc: float, fear: dict, no_fear: dict) -> str:
        cells = [
            acc,
            fear["accuracy"],
            fear["misclassified"],
            fear["undecided"],
            no_fear["accuracy"],
            no_fear["misclassified"],
            no_fear["undecided"],
        ]
        return f"| {label} | " + " | ".join(f"{100 * c:.1f}" for c in cells) + " |"

    for r in results:
        lines.append(row(str(r.split_seed), r.accuracy, r.report["fear"], r.report["no_fear"]))
    mean = {
        name: {key: float(np.mean([r.report[name][key] for r in results])) for key in results[0].report[name]}
        for name in ("fear", "no_fear")
    }
    lines.append(row("mean", float(np.mean([r.accuracy for r in results])), mean["fear"], mean["no_fear"]))
    lines.append("| paper (real data) | – | 87 | 3 | – | 83 | 1.5 | – |")
    return "\n".join(lines)


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m cogblocks.training.encoder",
        description="Train the encoding classifier of the PoP of Amplification (5 random 70/30 splits).",
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the splits and the weights (default 0)")
    parser.add_argument(
        "--epochs",
        type=int,
        default=EncoderConfig.epochs,
        help=f"passes over the training data (default {EncoderConfig.epochs})",
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=DEFAULT_OUT,
        help=f"checkpoint to write (default {DEFAULT_OUT} in the working directory; the shipped one is {SHIPPED})",
    )
    return parser


def main(argv: Sequence[str] | None = None) -> None:
    """Command-line entry point: cross-validate, print the table, save the best network."""
    args = _parser().parse_args(argv)

    torch.set_num_threads(1)
    config = EncoderConfig(epochs=args.epochs)
    started = time.perf_counter()
    library = generate_reach_library(config.library_seed)
    results = cross_validate(config, args.seed, library=library)
    best = max(results, key=lambda r: r.accuracy)
    checkpoint = {
        "state_dict": best.network.state_dict(),
        "hidden": config.hidden,
        "dropout": config.dropout,
        "library_seed": config.library_seed,
        "library_sha256": library_fingerprint(library),
        "library_summary": library_summary(library),
        "val_fraction": config.val_fraction,
        "split_seed": best.split_seed,
        "seed": args.seed,
        "config": asdict(config),
        "cv": [
            {
                "split_seed": r.split_seed,
                "accuracy": r.accuracy,
                **{f"{name}_{key}": value for name, rep in r.report.items() for key, value in rep.items()},
            }
            for r in results
        ],
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    torch.save(checkpoint, args.out)
    print(format_table(results))
    print(
        f"saved the network of split seed {best.split_seed} (accuracy {best.accuracy:.3f}) to {args.out.resolve()} "
        f"after {time.perf_counter() - started:.0f} s"
    )


if __name__ == "__main__":
    main()
