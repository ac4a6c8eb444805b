"""``cogblocks run amplification``: the PoP of Amplification on the bundled library, or the whole chain on a file."""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from cogblocks.amplification.smoothing import STEP_LIMIT
from cogblocks.cli_options import OUTPUT_FOLDER, SEED, STEP, plot_output, print_result

__all__ = ["add_amplification_parser", "step_limit_option"]

#: Options that only the whole chain on a library file reads, by their attribute.
_LIBRARY_ONLY = {
    "--out": "out",
    "--quick": "quick",
    "--seed": "seed",
    "--label-field": "label_field",
    "--dt": "dt",
    "--unit": "unit",
}
_LIBRARY_SUFFIXES = (".mat", ".npz", ".csv")


def step_limit_option(text: str) -> float | None:
    """``--step-limit``: a multiple of the human's largest step (> 0), or ``none`` for the rule's own steps."""
    if text.strip().lower() == "none":
        return None
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected a multiple of the human's largest step (> 0) or 'none', got {text!r}"
        ) from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"expected a multiple of the human's largest step (> 0), got {text}")
    return value


def _library_file(text: str) -> str:
    path = Path(text)
    if path.is_dir():
        raise argparse.ArgumentTypeError(f"{text!r} is a folder: give a library file ({', '.join(_LIBRARY_SUFFIXES)})")
    if not path.is_file():
        raise argparse.ArgumentTypeError(f"{text!r}: no such file")
    if path.suffix.lower() not in _LIBRARY_SUFFIXES:
        raise argparse.ArgumentTypeError(
            f"{text!r}: unknown library format {path.suffix or 'without a suffix'!r} "
            f"(expected {', '.join(_LIBRARY_SUFFIXES)})"
        )
    return text


def add_amplification_parser(targets: Any, common: Callable[[argparse.ArgumentParser], None]) -> None:
    """Add ``run amplification`` to the ``run`` command's targets; ``common`` adds ``--json`` and ``--plot``."""
    amplification = targets.add_parser(
        "amplification", help="PoP of Amplification: encode fear in held-out no-fear movements, with and without RL"
    )
    amplification.add_argument(
        "--variant",
        action="append",
        choices=("blend", "blend_rl", "optimised"),
        help="variant(s) to run (default: all three); 'optimised' is the casadi blending; repeatable",
    )
    amplification.add_argument(
        "--step-limit",
        type=step_limit_option,
        default=STEP_LIMIT,
        metavar="FACTOR|none",
        help="limit the altered velocity's per-tick step to FACTOR × the human's largest so far (VelocityStepLimiter; "
        f"default {STEP_LIMIT:g}: within the human's own); none: the blending rule's own steps, as in the deliverable",
    )
    amplification.add_argument(
        "--library", type=_library_file, metavar="FILE", help="run the whole chain on FILE (.mat, .npz, .csv)"
    )
    amplification.add_argument(
        "--out", type=OUTPUT_FOLDER, metavar="DIR", help="with --library: where weights, tables, report go"
    )
    amplification.add_argument("--quick", action="store_true", help="with --library: short training runs")
    amplification.add_argument("--seed", type=SEED, help="with --library: seed of split and training (default 0)")
    amplification.add_argument("--label-field", metavar="NAME", help="with --library: the fear label's name")
    amplification.add_argument("--dt", type=STEP, metavar="SECONDS", help="with --library: the sampling step")
    amplification.add_argument(
        "--unit",
        choices=("m", "cm", "mm"),
        help="with --library: the file's length unit (velocities in it per second), converted to mm "
        "(default: an .npz file's own unit key, mm otherwise)",
    )
    common(amplification)
    amplification.set_defaults(handler=_run_amplification)


def _percent(x: float | None) -> str:
    return "–" if x is None else f"{100 * x:.0f} %"


def _run_amplification(args: argparse.Namespace) -> int:
    if args.library is not None:
        return _run_amplification_pipeline(args)
    given = [option for option, value in _LIBRARY_ONLY.items() if getattr(args, value) not in (None, False)]
    if given:
        raise ValueError(f"{', '.join(given)} appl{'ies' if len(given) == 1 else 'y'} to --library FILE only")
    from cogblocks.diagrams.amplification import PAPER, plot_amplification, run_amplification

    variants = ("blend", "blend_rl", "optimised") if args.variant is None else tuple(args.variant)
    result = run_amplification(variants, step_limit=args.step_limit)
    # the other direction: remove fear
    result["e_des_0"] = run_amplification(variants, e_des=0, step_limit=args.step_limit)

    def judged(row: dict[str, Any]) -> str:
        shares = ", ".join(f"{name} {_percent(share)}" for name, share in row["judges"].items())
        return f"; independent judges: {shares}"

    def render(r: dict[str, Any]) -> str:
        lines = ["PoP of Amplification: held-out no-fear movements of the synthetic library, made to encode fear"]
        for name, row in r.items():
            if name == "e_des_0":
                continue
            paper = PAPER.get(name)
            if paper is None:  # no published figure: the optimised variant
                lines.append(
                    f"  {name:>9}: encoded {_percent(row['encoded'])}, terminal ok {_percent(row['terminal_ok'])}, "
                    f"final distance {row['final_distance_mm']:.1f} mm, n {row['n']}; CPU time per tick "
                    f"p50 {row['solve_ms_p50']:.1f} ms, p99 {row['solve_ms_p99']:.1f} ms (per decision p99 "
                    f"{row['decision_ms_p99']:.1f} ms), fallbacks {row['fallbacks']} of {row['decisions']}"
                    + judged(row)
                )
                continue
            distance = "–" if paper["final_distance_mm"] is None else f"{paper['final_distance_mm']:.0f} mm"
            lines.append(
                f"  {name:>9}: encoded {_percent(row['encoded'])} (paper {_percent(paper['encoded'])}), "
                f"terminal ok {_percent(row['terminal_ok'])} (paper {_percent(paper['terminal_ok'])}), "
                f"final distance {row['final_distance_mm']:.1f} mm (paper {distance}), "
                f"n {row['n']} (paper {paper['n']})" + judged(row)
            )
        lines.append("Held-out fear movements, fear removed (e_des = 0)")
        for name, row in r["e_des_0"].items():
            lines.append(
                f"  {name:>9}: encoded {_percent(row['encoded'])}, terminal ok {_percent(row['terminal_ok'])}, "
                f"n {row['n']}" + judged(row)
            )
        return "\n".join(lines)

    print_result(result, args.json, render)
    plot_output(args.plot, plot_amplification)
    return 0


def _run_amplification_pipeline(args: argparse.Namespace) -> int:
    from cogblocks.training.pipeline import run_pipeline

    if args.out is None:
        raise ValueError("--library needs --out DIR for the weights, tables and report")
    report = run_pipeline(
        args.library,
        args.out,
        seed=0 if args.seed is None else args.seed,
        quick=args.quick,
        label_field=args.label_field,
        dt=args.dt,
        unit=args.unit,
        step_limit=args.step_limit,
        log=lambda line: print(line, file=sys.stderr, flush=True),
    )
    print_result(report, args.json, _render_pipeline)
    return 0


def _render_pipeline(report: dict[str, Any]) -> str:
    library, split = report["library"], report["split"]
    lines = [
        f"library of {library['n']} movements (dt {library['dt']:g} s, "
        f"RMS speed {library['speed_rms_mm_s']:.0f} mm/s), seed {split['seed']}: "
        f"{split['train']} to train, {split['held_out']} held out",
        f"  encoder accuracy on the held-out movements {100 * report['encoder_held_out_accuracy']:.0f} %",
    ]
    for direction, rows in report["directions"].items():
        lines.append(f"held-out movements, {direction}:")
        for name, row in rows.items():
            encoded, terminal = _percent(row.get("encoded")), _percent(row.get("terminal_ok"))
            lines.append(f"  {name:>9}: encoded {encoded}, terminal ok {terminal}, n {row.get('n')}")
    return "\n".join(lines)
