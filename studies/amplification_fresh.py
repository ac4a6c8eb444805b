"""The shipped amplification chain on a freshly generated library: humans nobody has tuned on.

Usage::

    python -m studies.amplification_fresh --library-seed 2027 [--share 0.3] [--limit N]
        [--variants blend blend_rl optimised] [--json]
        [--profile-members P] [--kinematic-members K] [--kinematic-weights FILE ...]
        [--solve-ticks N] [--time-limit-ms T] [--realism R] [--components C] [--emit E] [--margin M]
        [--removal-margin M] [--guard-rest 0|1] [--guard-margin G] [--gradient stacked|blocks] [--predict-setup 0|1]
        [--neighbours K] [--terminal-margin MM] [--front-end recorded|kalman] [--noise-mm MM]
        [--smoothing-hz HZ|auto|none]
    python -m studies.amplification_fresh --library-seed 3000 --real

The held-out movements of the shipped split have been looked at in every round of tuning, so their
figures grow optimistic. Here the humans come from ``generate_reach_library(library_seed)``, a seed no
network, judge, setting or test used (participants with new styles, too): every movement of it that
does not encode ``e_des`` is replayed through the *shipped* chain unchanged (the projector's library
is the shipped training part, the same encoder, w̃, corrector, blender ensemble, judges and
subspace), in both directions; ``--share`` replays a seeded, stratified share of it instead
(``ReachLibrary.split(share, 0)``'s second part, as large as the held-out part for 0.3). Prints the rows
of :func:`~cogblocks.diagrams.amplification.run_amplification` (``e_des = 1`` at the top level,
``e_des = 0`` under ``"e_des_0"``). ``--profile-members``, ``--kinematic-members`` and ``--kinematic-weights``
replace the constrained networks, ``--solve-ticks``, ``--time-limit-ms``, ``--realism``, ``--components``,
``--emit``, ``--margin``, ``--removal-margin``, ``--guard-rest``, ``--guard-margin``, ``--gradient``,
``--predict-setup``, ``--neighbours`` and ``--terminal-margin`` the optimised blender's settings (as
``amplification_inner``'s), to try a setting on a *validation* library (a seed declared as such before it is looked
at); without them the chain is the shipped one. ``--front-end kalman`` (with ``--noise-mm``) feeds the architecture
the Kalman estimator's tracking of the positions instead of the recorded velocity, as on a live stream;
``--smoothing-hz`` sets its velocity's low-pass (``auto``: chosen from the noise; ``none``: the estimate as it is).
``--real`` prints instead what the shipped judges decide on the library's *real* movements
(:func:`real_shares`): how often the ensemble judge calls a real movement of ``e_des`` so, the scale of its
share on the altered ones.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch

from cogblocks.amplification.emission import EMISSIONS
from cogblocks.amplification.encoder import FEAR, NO_FEAR
from cogblocks.amplification.linearised import GRADIENTS
from cogblocks.amplification.smoothing import STEP_LIMIT
from cogblocks.amplification.subspace import movement_subspace
from cogblocks.data.reach import ReachLibrary, generate_reach_library
from cogblocks.diagrams.amplification import SMOOTHING_HZ, run_amplification
from cogblocks.diagrams.amplification_setup import (
    OPTIMISED,
    AmplificationSetup,
    amplification_judges,
    amplification_setup,
    blender_ensembles,
    blender_networks,
)
from cogblocks.experiments.amplification_cli import step_limit_option

__all__ = ["FRESH_SEED", "fresh_setup", "main", "real_shares", "run_fresh"]

#: The library seed of the fresh evaluation: chosen before any result on it was seen, used nowhere else.
FRESH_SEED = 2027


def fresh_setup(library_seed: int, e_des: int, humans: ReachLibrary | None = None) -> AmplificationSetup:
    """The shipped setup for ``e_des`` whose validation movements are a fresh library's.

    ``library`` is the shipped training part followed by the fresh movements (``humans``, by default
    ``generate_reach_library(library_seed)``); ``train`` indexes the former, ``val`` the latter; the
    projector's library, encoder, w̃ and subspace are the shipped ones.
    """
    shipped = amplification_setup(None, e_des)
    fresh = generate_reach_library(library_seed) if humans is None else humans
    base = shipped.movements
    if fresh.max_len != base.max_len or fresh.dt != base.dt:
        raise ValueError(
            f"fresh_setup: the fresh movements need the shipped library's window and step ({base.max_len} samples "
            f"of {base.dt} s), got {fresh.max_len} of {fresh.dt} s"
        )
    fields = ("velocity", "position", "length", "fear", "subject", "target")
    library = ReachLibrary(**{f: np.concatenate([getattr(base, f), getattr(fresh, f)]) for f in fields}, dt=base.dt)
    train, val = np.arange(len(base)), np.arange(len(base), len(library))
    return AmplificationSetup(library, train, val, base, shipped.encoder, shipped.table, e_des, shipped.subspace)


def run_fresh(
    library_seed: int = FRESH_SEED,
    variants: Sequence[str] = ("blend", "blend_rl", "optimised"),
    *,
    limit: int | None = None,
    share: float = 1.0,
    humans: ReachLibrary | None = None,
    directions: Sequence[int] = (1, 0),
    members: dict[str, int] | None = None,
    kinematic_weights: Sequence[str] | None = None,
    optimised: Mapping[str, Any] | None = None,
    front_end: str = "recorded",
    noise_mm: float = 0.0,
    smoothing_hz: float | str | None = SMOOTHING_HZ,
    step_limit: float | None = STEP_LIMIT,
) -> dict[str, Any]:
    """Both directions on the fresh movements, keyed as ``cogblocks run amplification --json``.

    ``share`` < 1 keeps the seeded, stratified ``ReachLibrary.split(share, 0)`` validation part of them;
    ``directions`` are the ``e_des`` run. ``members`` (``{"profile": P, "kinematic": K}``) and ``kinematic_weights``
    (the files of the kinematic networks, :func:`blender_ensembles`) replace the shipped constrained networks and
    ``optimised`` some of :data:`OPTIMISED` (``components``: the realism subspace's, computed on the shipped training
    part), to try a setting on a validation library; by default the chain is the shipped one. ``front_end`` and
    ``noise_mm`` are :func:`~cogblocks.diagrams.amplification.pop_amplification`'s: ``"kalman"`` replays the tracked
    positions, with that much noise, through the Kalman estimator, as on a live motion-capture stream, its velocity
    smoothed at ``smoothing_hz`` (None: not smoothed) and gated at rest. ``step_limit`` is
    :func:`~cogblocks.diagrams.amplification.pop_amplification`'s (the shipped one by default; None: the
    blending rules' own steps).
    """
    ensembles = blender_ensembles(kinematic_weights) if kinematic_weights else None
    settings = {**OPTIMISED, **(optimised or {})}
    components = int(settings.pop("components"))
    if share < 1.0:
        humans = generate_reach_library(library_seed) if humans is None else humans
        humans = humans.subset(humans.split(share, 0)[1])
    rows: dict[str, Any] = {"library_seed": library_seed, "share": share}
    for e_des in directions:
        setup = fresh_setup(library_seed, e_des, humans)
        if components != OPTIMISED["components"]:
            setup = dataclasses.replace(setup, subspace=movement_subspace(setup.movements, e_des, components))
        result = run_amplification(
            variants, limit=limit, e_des=e_des, setup=setup, judges=amplification_judges(),
            blender_networks=blender_networks(setup.encoder, **(members or {}), ensembles=ensembles),
            optimised=settings, front_end=front_end, noise_mm=noise_mm, smoothing_hz=smoothing_hz,
            step_limit=step_limit,
        )  # fmt: skip
        rows.update(result) if e_des == 1 else rows.update(e_des_0=result)
    return rows


def real_shares(library_seed: int, humans: ReachLibrary | None = None) -> dict[str, Any]:
    """The shipped judges' decisions on the real movements of ``generate_reach_library(library_seed)`` (or ``humans``).

    Per class (``"fear"``, ``"no_fear"``) and judge: ``correct``, the share of the class's movements decided as
    their class, and ``wrong``, decided as the other class (the ensemble judge leaves the rest undecided); ``n``.
    """
    library = generate_reach_library(library_seed) if humans is None else humans
    decisions = amplification_judges().decide(library.velocity)
    rows: dict[str, Any] = {"library_seed": library_seed}
    for name, fear, own, other in (("fear", True, FEAR, NO_FEAR), ("no_fear", False, NO_FEAR, FEAR)):
        members = library.fear == fear
        rows[name] = {"n": int(members.sum())} | {
            judge: {"correct": float(np.mean(d[members] == own)), "wrong": float(np.mean(d[members] == other))}
            for judge, d in decisions.items()
        }
    return rows


def _cutoff(text: str) -> float | str | None:
    """``--smoothing-hz``: a cut-off in Hz, ``auto`` or ``none``."""
    if text.lower() in ("none", "auto"):
        return None if text.lower() == "none" else "auto"
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"a cut-off in Hz, 'auto' or 'none', got {text!r}") from None


def main(argv: Sequence[str] | None = None) -> int:
    """Command-line entry point: print both directions on a fresh library (JSON with ``--json``)."""
    parser = argparse.ArgumentParser(prog="python -m studies.amplification_fresh", description=__doc__)
    parser.add_argument("--library-seed", type=int, default=FRESH_SEED, help=f"default {FRESH_SEED}")
    parser.add_argument("--share", type=float, default=1.0, help="seeded stratified share replayed (default 1)")
    parser.add_argument("--limit", type=int, default=None, help="replay only the first N movements per direction")
    parser.add_argument("--variants", nargs="+", default=["blend", "blend_rl", "optimised"])
    parser.add_argument(
        "--e-des", type=int, choices=(0, 1), nargs="+", default=[1, 0], help="directions (default both)"
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--profile-members", type=int, default=None, help="default CONSTRAINED_MEMBERS'")
    parser.add_argument("--kinematic-members", type=int, default=None, help="default CONSTRAINED_MEMBERS'")
    parser.add_argument(
        "--kinematic-weights", nargs="+", default=None, metavar="FILE",
        help="ensemble checkpoints the kinematic networks are taken from, in order (default the shipped one)",
    )  # fmt: skip
    parser.add_argument("--solve-ticks", type=int, default=OPTIMISED["solve_ticks"])
    parser.add_argument("--time-limit-ms", type=float, default=OPTIMISED["time_limit_ms"])
    parser.add_argument("--realism", type=float, default=OPTIMISED["realism"])
    parser.add_argument("--components", type=int, default=OPTIMISED["components"])
    parser.add_argument("--emit", default=OPTIMISED.get("emit", "human"), choices=EMISSIONS)
    parser.add_argument("--margin", type=float, default=OPTIMISED["margin"])
    parser.add_argument("--removal-margin", type=float, default=OPTIMISED.get("removal_margin"))
    parser.add_argument("--guard-rest", type=int, choices=(0, 1), default=int(OPTIMISED.get("guard_rest", False)))
    parser.add_argument("--guard-margin", type=float, default=OPTIMISED.get("guard_margin", 0.0))
    parser.add_argument("--gradient", default=OPTIMISED.get("gradient", "blocks"), choices=GRADIENTS)
    parser.add_argument("--predict-setup", type=int, choices=(0, 1), default=int(OPTIMISED.get("predict_setup", True)))
    parser.add_argument("--neighbours", type=int, default=OPTIMISED.get("neighbours", 1), help="movements predicted on")
    parser.add_argument("--terminal-margin", type=float, default=OPTIMISED.get("terminal_margin", 5.0), help="mm")
    parser.add_argument("--front-end", default="recorded", choices=("recorded", "kalman"), help="default recorded")
    parser.add_argument("--noise-mm", type=float, default=0.0, help="with --front-end kalman: position noise, mm")
    parser.add_argument(
        "--smoothing-hz", type=_cutoff, default=SMOOTHING_HZ, metavar="HZ|auto|none",
        help=f"with --front-end kalman: the velocity estimate's low-pass cut-off (default {SMOOTHING_HZ}; none: off)",
    )  # fmt: skip
    parser.add_argument(
        "--step-limit", type=step_limit_option, default=STEP_LIMIT, metavar="FACTOR|none",
        help=f"the altered velocity's per-tick step at most FACTOR x the human's largest step (default {STEP_LIMIT:g})",
    )  # fmt: skip
    parser.add_argument("--real", action="store_true", help="the judges on the library's real movements (JSON)")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    if args.real:
        print(json.dumps(real_shares(args.library_seed)))
        return 0
    names = ("solve_ticks", "time_limit_ms", "realism", "components", "emit", "margin", "removal_margin")
    names += ("guard_margin", "gradient", "neighbours", "terminal_margin")
    flags = {"guard_rest": bool(args.guard_rest), "predict_setup": bool(args.predict_setup)}
    optimised = {name: getattr(args, name) for name in names} | flags
    given = {"profile": args.profile_members, "kinematic": args.kinematic_members}
    members = {name: count for name, count in given.items() if count is not None}
    rows = run_fresh(args.library_seed, args.variants, limit=args.limit, share=args.share, directions=args.e_des,
                     members=members, kinematic_weights=args.kinematic_weights, optimised=optimised,
                     front_end=args.front_end, noise_mm=args.noise_mm, smoothing_hz=args.smoothing_hz,
                     step_limit=args.step_limit)  # fmt: skip
    if args.json:
        print(json.dumps(rows))
        return 0
    for key, direction in (("encode fear", rows), ("remove fear", rows.get("e_des_0", {}))):
        for variant in (v for v in args.variants if v in direction):
            r = direction[variant]
            print(
                f"{key} {variant}: encoded {r['encoded']:.0%}, ensemble judge {r['encoded_independent']:.0%}, "
                f"kinematic {r['judges']['kinematic']:.0%}, within 20 mm {r['terminal_ok']:.0%}, n {r['n']}"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
