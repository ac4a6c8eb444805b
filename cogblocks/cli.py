"""The ``cogblocks`` command line: run the ready diagrams and print their figures."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable, Sequence
from typing import Any

__all__ = ["main"]


def _print_result(result: dict[str, Any], as_json: bool, render: Callable[[dict[str, Any]], str]) -> None:
    if as_json:
        print(json.dumps(result))
    else:
        print(render(result))


def _run_demo(args: argparse.Namespace) -> int:
    from cogblocks.diagrams.demo import kuramoto_demo

    result = kuramoto_demo(duration=args.duration, plot=args.plot)
    _print_result(
        result,
        args.json,
        lambda r: (
            f"Kuramoto group of {r['n']} (ring, gain {r['gain']:.4f}) over {r['duration']} s: "
            f"time-averaged order parameter {r['r_mean']:.4f}"
        ),
    )
    return 0


def _run_sync(args: argparse.Namespace) -> int:
    from cogblocks.diagrams.sync import MOTIONS, plot_sync, run_sync

    motions = list(MOTIONS) if args.policy is None else args.policy
    if args.random is not None:
        return _run_sync_heldout(args, motions)
    group = 1 if args.group is None else args.group
    result = run_sync(group, motions, domain=args.domain)
    if args.plot:
        plot_sync(group, motions[0], args.plot)

    def render(r: dict[str, Any]) -> str:
        lines = [f"Group {r['group']}: time-averaged order parameter without L2 {r['r_without']:.4f}"]
        for row in r["results"]:
            lines.append(
                f"  with L2, {row['policy']:>10}: {row['r_with']:.4f} ({row['change_pct']:+.2f} %), "
                f"|θ_L2 − θ_L0| mean {row['mean_dev_rad']:.3f} rad, max {row['max_dev_rad']:.3f} rad"
            )
        return "\n".join(lines)

    _print_result(result, args.json, render)
    return 0


def _run_sync_heldout(args: argparse.Namespace, motions: list[str]) -> int:
    from cogblocks.experiments.sync_heldout import heldout_table

    if args.plot or args.domain != "phase":
        raise ValueError("--random evaluates in the phase domain and draws no figure: drop --plot and --domain")
    result = heldout_table(args.random, args.seed, motions, workers=args.workers, max_duration=args.max_duration)

    def render(r: dict[str, Any]) -> str:
        lines = [
            f"{r['n_groups']} held-out random groups (test split, seed {r['seed']}): change of the mean order "
            "parameter with L2",
            f"  {'policy':>10}  lowered  mean %   p5 %  worst %  of bound  |θ_L2 − θ_L0| mean / max rad",
        ]
        for row in r["policies"]:
            bound = "–" if row["mean_bound_fraction"] is None else f"{row['mean_bound_fraction']:.2f}"
            lines.append(
                f"  {row['policy']:>10}  {100 * row['lowered_share']:5.1f} %  {row['mean_change_pct']:+6.2f} "
                f"{row['p5_change_pct']:+6.2f}  {row['worst_change_pct']:+7.2f}  {bound:>8}  "
                f"{row['mean_dev_rad']:.3f} / {row['max_dev_rad']:.3f}"
            )
        return "\n".join(lines)

    _print_result(result, args.json, render)
    return 0


def _run_phase3d(args: argparse.Namespace) -> int:
    from cogblocks.diagrams.phase3d import phase3d_accuracy, plot_phase3d, run_phase_chain

    result = phase3d_accuracy(n_trajectories=args.trajectories, seed=args.seed)
    result["chain"] = run_phase_chain(seed=args.seed)
    if args.plot:
        plot_phase3d(args.plot, seed=args.seed)

    def render(r: dict[str, Any]) -> str:
        chain = r["chain"]
        return (
            f"3D phase estimation over {r['n_trajectories']} synthetic trajectories (after the first period):\n"
            f"  against ground truth:        mean {r['mean_error_rad']:.3f} rad, "
            f"95th percentile {r['p95_error_rad']:.3f} rad\n"
            f"  against offline PCA-Hilbert: mean {r['mean_error_vs_offline_rad']:.3f} rad, "
            f"95th percentile {r['p95_error_vs_offline_rad']:.3f} rad\n"
            f"phase chain (3D → phase → L2 → 3D avatar, group 3): r {chain['r_mean']:.3f}, "
            f"|θ_L2 − θ_L0| mean {chain['mean_dev_rad']:.3f} rad, valid from {chain['valid_from_s']:.2f} s"
        )

    _print_result(result, args.json, render)
    return 0


def _run_amplification(args: argparse.Namespace) -> int:
    from cogblocks.diagrams.amplification import PAPER, plot_amplification, run_amplification

    result = run_amplification() if args.variant is None else run_amplification(tuple(args.variant))
    if args.plot:
        plot_amplification(args.plot)

    def percent(x: float | None) -> str:
        return "–" if x is None else f"{100 * x:.0f} %"

    def render(r: dict[str, Any]) -> str:
        lines = ["PoP of Amplification: held-out no-fear movements of the synthetic library, made to encode fear"]
        for name, row in r.items():
            paper = PAPER.get(name)
            if paper is None:  # no published figure: the optimised variant
                lines.append(
                    f"  {name:>9}: encoded {percent(row['encoded'])}, terminal ok {percent(row['terminal_ok'])}, "
                    f"final distance {row['final_distance_mm']:.1f} mm, n {row['n']}; time per decision "
                    f"p50 {row['solve_ms_p50']:.1f} ms, p99 {row['solve_ms_p99']:.1f} ms, fallbacks {row['fallbacks']}"
                )
                continue
            distance = "–" if paper["final_distance_mm"] is None else f"{paper['final_distance_mm']:.0f} mm"
            lines.append(
                f"  {name:>9}: encoded {percent(row['encoded'])} (paper {percent(paper['encoded'])}), "
                f"terminal ok {percent(row['terminal_ok'])} (paper {percent(paper['terminal_ok'])}), "
                f"final distance {row['final_distance_mm']:.1f} mm (paper {distance}), "
                f"n {row['n']} (paper {paper['n']})"
            )
        return "\n".join(lines)

    _print_result(result, args.json, render)
    return 0


def _build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="cogblocks",
        description="Run the cognitive architectures of L1/L2 virtual humans as discrete-time block diagrams.",
    )
    parser.add_argument("--version", action="version", version=_version())
    commands = parser.add_subparsers(dest="command", metavar="COMMAND")
    run = commands.add_parser("run", help="run a ready diagram and print its figures")
    targets = run.add_subparsers(dest="target", metavar="TARGET")
    run.set_defaults(handler=lambda _: run.print_help() or 2)

    sync = targets.add_parser(
        "sync", help="PoP of Social Connectedness: Table 3 for one group, or a held-out table on random groups"
    )
    which = sync.add_mutually_exclusive_group()
    which.add_argument("--group", type=int, choices=(1, 2, 3), help="Table 2's group number (default 1)")
    which.add_argument(
        "--random", type=_at_least_one, metavar="N", help="evaluate every policy on N random groups of the test split"
    )
    sync.add_argument("--seed", type=int, default=0, help="seed of the random groups (default 0)")
    sync.add_argument(
        "--max-duration",
        type=float,
        metavar="S",
        help="with --random: cut every group to at most S simulated seconds (a quick look)",
    )
    sync.add_argument(
        "--workers", type=_at_least_one, default=1, metavar="W", help="processes for --random (default 1)"
    )
    sync.add_argument(
        "--policy", action="append", metavar="NAME", help="motion computer(s) to run (default: all); repeatable"
    )
    sync.add_argument(
        "--domain",
        choices=("phase", "position"),
        default="phase",
        help="'position': the L2 works on phases estimated from simulated arm positions (default 'phase')",
    )
    _common(sync)
    sync.set_defaults(handler=_run_sync)

    phase3d = targets.add_parser("phase3d", help="3D phase estimation accuracy and the 3D phase chain")
    phase3d.add_argument("--trajectories", type=int, default=30, help="synthetic trajectories (default 30)")
    phase3d.add_argument("--seed", type=int, default=0, help="seed of the trajectories (default 0)")
    _common(phase3d)
    phase3d.set_defaults(handler=_run_phase3d)

    amplification = targets.add_parser(
        "amplification", help="PoP of Amplification: encode fear in held-out no-fear movements, with and without RL"
    )
    amplification.add_argument(
        "--variant",
        action="append",
        choices=("blend", "blend_rl", "optimised"),
        help="variant(s) to run (default: all three); 'optimised' is the casadi blending; repeatable",
    )
    _common(amplification)
    amplification.set_defaults(handler=_run_amplification)

    demo = targets.add_parser("demo", help="a Kuramoto group (Table 2, group 3) without L2")
    demo.add_argument("--duration", type=float, default=300.0, help="simulated seconds (default 300)")
    _common(demo)
    demo.set_defaults(handler=_run_demo)
    return parser


def _at_least_one(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    p.add_argument("--plot", metavar="FILE", help="save a figure to FILE (png, pdf, svg)")


def _version() -> str:
    from cogblocks import __version__

    return f"cogblocks {__version__}"


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``cogblocks`` command."""
    parser = _build_parser()
    args = parser.parse_args(argv)
    handler = getattr(args, "handler", None)
    if handler is None:
        parser.print_help()
        return 0 if args.command is None else 2
    try:
        return handler(args)
    except (ValueError, OSError) as exc:
        print(f"cogblocks: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
