"""The inner split on which the optimised blender's settings were chosen, never the held-out movements.

Usage::

    python -m studies.amplification_inner --e-des 1 --limit 30 [--components 12]
        [--realism 1000] [--margin 0.09] [--time-limit-ms 3.5] [--solver linearised] [--solve-ticks 1]
        [--iterations 10] [--profile-members 2] [--kinematic-members 0] [--emit human|plan|tail] [--track-past 0|1]
        [--removal-margin M] [--guard-rest 0|1] [--guard-margin G] [--kinematic-weights FILE ...]
        [--gradient stacked|blocks] [--predict-setup 0|1]

The training part of the shipped encoder's split is split again, seeded and stratified
(``ReachLibrary.split(0.3, 100)``); w̃ and the realism subspace are computed on the inner training
part, and the first ``limit`` inner movements that do not encode ``e_des`` are replayed through the
optimised blender (the blender ensemble, as ``cogblocks run amplification``) and scored by the
shipped judges. The inner movements were in the training data of the networks and judges, so the
shares only rank settings (docs/validation/amplification.md). Prints one JSON line: the
settings (``solve_ticks`` among them), then the row, whose count of ticks that worked on a decision is
``ticks_worked`` (``solve_ticks`` in :func:`~cogblocks.diagrams.amplification.run_amplification`'s row).
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from typing import Any

import torch

from cogblocks.amplification import solution_table
from cogblocks.amplification.emission import EMISSIONS
from cogblocks.amplification.linearised import GRADIENTS
from cogblocks.amplification.subspace import movement_subspace
from cogblocks.diagrams.amplification import run_amplification
from cogblocks.diagrams.amplification_setup import (
    CONSTRAINED_MEMBERS,
    OPTIMISED,
    AmplificationSetup,
    amplification_judges,
    amplification_setup,
    blender_ensembles,
    blender_networks,
)

__all__ = ["INNER_SEED", "evaluate", "inner_setup", "main"]

INNER_SEED = 100


def inner_setup(
    e_des: int, components: int = int(OPTIMISED["components"]), seed: int = INNER_SEED
) -> AmplificationSetup:
    """The inner split of the shipped training part: ``library`` is the training part, ``val`` its inner 30 %."""
    outer = amplification_setup(None, 1)
    library = outer.movements
    train, val = library.split(0.3, seed)
    movements = library.subset(train)
    table = solution_table(outer.encoder, movements, e_des)
    subspace = movement_subspace(movements, e_des, components)
    return AmplificationSetup(library, train, val, movements, outer.encoder, table, e_des, subspace)


def evaluate(
    e_des: int,
    limit: int,
    components: int,
    members: dict[str, int] | None = None,
    kinematic_weights: Sequence[str] | None = None,
    **options: Any,
) -> dict[str, Any]:
    """The optimised row of :func:`run_amplification` on the first ``limit`` inner movements, with ``options``.

    ``members`` (``{"profile": P, "kinematic": K}``) overrides :data:`CONSTRAINED_MEMBERS`: the networks constrained;
    ``kinematic_weights`` the files the kinematic networks come from (:func:`blender_ensembles`; the shipped one).
    """
    setup = inner_setup(e_des, components)
    ensembles = blender_ensembles(kinematic_weights) if kinematic_weights else None
    networks = blender_networks(setup.encoder, **(members or {}), ensembles=ensembles)
    result = run_amplification(
        ("optimised",), limit=limit, e_des=e_des, setup=setup, judges=amplification_judges(),
        blender_networks=networks, optimised=options,
    )  # fmt: skip
    return result["optimised"]


def main(argv: Sequence[str] | None = None) -> int:
    """Command-line entry point: print the inner-split row of one setting as JSON."""
    defaults = {k: v for k, v in OPTIMISED.items() if k != "components"}
    parser = argparse.ArgumentParser(prog="python -m studies.amplification_inner", description=__doc__)
    parser.add_argument("--e-des", type=int, choices=(0, 1), default=1)
    parser.add_argument("--limit", type=int, default=30, help="inner movements replayed (default 30)")
    parser.add_argument("--components", type=int, default=int(OPTIMISED["components"]))
    parser.add_argument("--realism", type=float, default=defaults["realism"])
    parser.add_argument("--margin", type=float, default=defaults["margin"])
    parser.add_argument("--time-limit-ms", type=float, default=defaults["time_limit_ms"])
    parser.add_argument("--solver", default=defaults["solver"], choices=("linearised", "sqpmethod", "ipopt"))
    parser.add_argument("--solve-ticks", type=int, default=defaults.get("solve_ticks", 1))
    parser.add_argument("--iterations", type=int, default=defaults.get("iterations", 10))
    parser.add_argument("--emit", default=defaults.get("emit", "human"), choices=EMISSIONS)
    parser.add_argument("--removal-margin", type=float, default=defaults.get("removal_margin"),
                        help="margin for e_des 0 (default --margin)")  # fmt: skip
    parser.add_argument("--guard-rest", type=int, choices=(0, 1), default=int(defaults.get("guard_rest", False)))
    parser.add_argument("--guard-margin", type=float, default=defaults.get("guard_margin", 0.0))
    parser.add_argument("--gradient", default=defaults.get("gradient", "blocks"), choices=GRADIENTS)
    parser.add_argument("--predict-setup", type=int, choices=(0, 1), default=int(defaults.get("predict_setup", True)))
    parser.add_argument(
        "--track-past", type=int, choices=(0, 1), default=int(defaults.get("track_past", False)),
        help="1: the spread solve follows the emitted past (OptimalBlender(track_past=True))",
    )  # fmt: skip
    parser.add_argument(
        "--profile-members",
        type=int,
        default=CONSTRAINED_MEMBERS["profile"],
        help="networks of encoder_ensemble.pt constrained besides the encoder",
    )
    parser.add_argument(
        "--kinematic-members",
        type=int,
        default=CONSTRAINED_MEMBERS["kinematic"],
        help="networks of encoder_ensemble_kinematic.pt constrained",
    )
    parser.add_argument(
        "--kinematic-weights", nargs="+", default=None, metavar="FILE",
        help="ensemble checkpoints the kinematic networks are taken from, in order (default the shipped one)",
    )  # fmt: skip
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    options = {"realism": args.realism, "margin": args.margin, "time_limit_ms": args.time_limit_ms,
               "solve_ticks": args.solve_ticks, "iterations": args.iterations, "emit": args.emit,
               "track_past": bool(args.track_past), "removal_margin": args.removal_margin,
               "guard_rest": bool(args.guard_rest), "guard_margin": args.guard_margin, "gradient": args.gradient,
               "predict_setup": bool(args.predict_setup)}  # fmt: skip
    members = {"profile": args.profile_members, "kinematic": args.kinematic_members}
    row = evaluate(args.e_des, args.limit, args.components, members, args.kinematic_weights, solver=args.solver,
                   **options)  # fmt: skip
    if "solve_ticks" in row:  # the row's count of working ticks, not the option of the same name
        row["ticks_worked"] = row.pop("solve_ticks")
    print(json.dumps({"e_des": args.e_des, "components": args.components, **options, "solver": args.solver,
                      "members": members, "kinematic_weights": args.kinematic_weights, **row}))  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
