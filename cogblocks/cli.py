"""The ``cogblocks`` command line: run the ready diagrams and print their figures."""

from __future__ import annotations

import argparse
import json
import signal
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = ["main"]


# --- output ---------------------------------------------------------------------------------------------


def _run_demo(args: argparse.Namespace) -> int:
    from cogblocks.cli_options import plot_output, print_result, write_output
    from cogblocks.diagrams.demo import demo_run, plot_demo

    result, trace = demo_run(duration=args.duration)
    print_result(
        result,
        args.json,
        lambda r: (
            f"Kuramoto group of {r['n']} (ring, gain {r['gain']:.4f}) over {r['duration']} s: "
            f"time-averaged order parameter {r['r_mean']:.4f}"
        ),
    )
    if args.save_trace:
        write_output(args.save_trace, trace.save, "the trace")
    plot_output(args.plot, lambda path: plot_demo(path, duration=args.duration))
    return 0


def _run_sync(args: argparse.Namespace) -> int:
    from cogblocks.cli_options import plot_output, write_output
    from cogblocks.diagrams.naturalness import naturalness_text
    from cogblocks.diagrams.sync import DEFAULT_MOTION, DEFAULT_MOTIONS, MOTIONS, plot_sync, sync_table
    from cogblocks.experiments.heldout_cli import run_sync_heldout
    from cogblocks.experiments.sync import sync_trace

    if not args.handover and args.domain != "position":
        raise ValueError("--no-handover applies to --domain position only (the phase domain has no estimate to settle)")
    if args.random is not None:  # every policy unless some are named
        return run_sync_heldout(args, list(MOTIONS) if args.policy is None else args.policy)
    if args.split != "test" or args.no_bound or args.thorough_bound or args.max_duration is not None or args.noise:
        raise ValueError("--split, --no-bound, --thorough-bound, --max-duration and --noise apply to --random N only")
    # the main job: the published comparison and pop_sync's own default motion computer
    motions = list(dict.fromkeys([*DEFAULT_MOTIONS, DEFAULT_MOTION])) if args.policy is None else args.policy
    group = 1 if args.group is None else args.group
    if args.save_trace and len(motions) != 1:
        raise ValueError("--save-trace writes one run's trace: give exactly one --policy")
    if args.save_trace and (args.duration is not None or args.seed != 0):
        raise ValueError("--save-trace records the group's own run: drop --duration and --seed")
    options = {"duration": args.duration, "seed": args.seed, "blender": args.blender, "handover": args.handover}
    result: dict[str, Any] = {}
    try:
        for row in sync_table(group, motions, args.domain, **options):
            if not result:  # the first figure: r without L2
                result = {**row, "results": []}
                line = f"Group {row['group']}: time-averaged order parameter without L2 {row['r_without']:.4f}"
            else:
                result["results"].append(row)
                line = (
                    f"  with L2, {row['policy']:>10}: {row['r_with']:.4f} ({row['change_pct']:+.2f} %), "
                    f"|θ_L2 − θ_L0| mean {row['mean_dev_rad']:.3f} rad, max {row['max_dev_rad']:.3f} rad; "
                    + naturalness_text(row)
                )
            if not args.json:  # text streams, one line per figure as soon as it is known
                print(line, flush=True)
    except KeyboardInterrupt:  # --json: the figures known so far, marked as such
        if args.json and result:
            print(json.dumps({**result, "interrupted": True}), flush=True)
        raise
    if args.json:
        print(json.dumps(result), flush=True)
    if args.save_trace:
        write_output(
            args.save_trace,
            sync_trace(group, motions[0], args.domain, blender=args.blender, handover=args.handover).save,
            "the trace",
        )
    for motion, path in _figure_paths(args.plot, motions).items():  # one figure per policy that ran
        plot_output(path, lambda path, motion=motion: plot_sync(group, motion, path, domain=args.domain, **options))
    return 0


def _figure_paths(path: str | None, motions: list[str]) -> dict[str, str]:
    """``--plot FILE`` for one policy, ``FILE-<policy>`` (same folder and format) for each of several."""
    if not path:
        return {}
    if len(motions) == 1:
        return {motions[0]: path}
    file = Path(path)
    return {m: str(file.with_name(f"{file.stem}-{m}{file.suffix}")) for m in motions}


def _run_phase3d(args: argparse.Namespace) -> int:
    from cogblocks.cli_options import plot_output, print_result
    from cogblocks.diagrams.phase3d import phase3d_accuracy, plot_phase3d, run_phase_chain

    if not 30.0 <= args.rate <= 240.0:
        raise ValueError(f"--rate must be between 30 and 240 Hz, got {args.rate:g}")
    result = phase3d_accuracy(
        n_trajectories=args.trajectories, seed=args.seed, rate_hz=args.rate, motion_set=args.motion_set
    )
    result["chain"] = run_phase_chain(seed=args.seed)

    def render(r: dict[str, Any]) -> str:
        chain = r["chain"]
        return (
            f"3D phase estimation over {r['n_trajectories']} synthetic trajectories, set {r['set']!r}, "
            f"{r['rate_hz']:g} Hz (after the first period):\n"
            f"  against ground truth:        mean {r['mean_error_rad']:.3f} rad, "
            f"95th percentile {r['p95_error_rad']:.3f} rad\n"
            f"  against offline PCA-Hilbert: mean {r['mean_error_vs_offline_rad']:.3f} rad, "
            f"95th percentile {r['p95_error_vs_offline_rad']:.3f} rad\n"
            f"phase chain (3D → phase → L2 → 3D avatar, group 3): r {chain['r_mean']:.3f}, "
            f"|θ_L2 − θ_L0| mean {chain['mean_dev_rad']:.3f} rad, valid from {chain['valid_from_s']:.2f} s"
        )

    print_result(result, args.json, render)
    plot_output(args.plot, lambda path: plot_phase3d(path, seed=args.seed))
    return 0


def _run_phase1d(args: argparse.Namespace) -> int:
    from cogblocks.cli_options import plot_output, print_result
    from cogblocks.evaluation.phase1d import EVALUATION_SEEDS, evaluate_grid, plot_grid

    if not 1 <= args.signals <= len(EVALUATION_SEEDS) or not args.duration >= 10.0 or args.workers < 1:
        raise ValueError(
            f"--signals must be 1-{len(EVALUATION_SEEDS)}, --duration at least 10 s and --workers at least 1, "
            f"got {args.signals}, {args.duration:g}, {args.workers}"
        )
    result = evaluate_grid(seeds=EVALUATION_SEEDS[: args.signals], duration=args.duration, workers=args.workers)

    def render(r: dict[str, Any]) -> str:
        lines = ["1D phase estimation on simulated sensors (errors vs the true phase after two periods, rad)"]
        lines.append("  rate Hz   scale  quant.  noise   mean    p95  held %  Hilbert mean")
        for c in r["cells"]:
            lines.append(
                f"  {c['rate_hz']:7g} {c['scale']:7g} {c['quantised']:>7} {c['noise']:>6} {c['mean_error_rad']:6.3f} "
                f"{c['p95_error_rad']:6.3f} {100 * c['held_share']:7.2f} {c['hilbert_mean_error_rad']:13.3f}"
            )
        lines.append(
            f"worst: mean {r['worst_mean_error_rad']:.3f} rad, p95 {r['worst_p95_error_rad']:.3f} rad, "
            f"held {100 * r['worst_held_share']:.2f} %"
        )
        return "\n".join(lines)

    print_result(result, args.json, render)
    plot_output(args.plot, lambda path: plot_grid(result, path))
    return 0


def _build_parser() -> argparse.ArgumentParser:
    from cogblocks.cli_options import COUNT, DURATION, POLICY, SEED, STEP
    from cogblocks.experiments.amplification_cli import add_amplification_parser
    from cogblocks.experiments.cli import add_sweep_parser
    from cogblocks.experiments.recordings_cli import add_analyse_parser, add_recording_options
    from cogblocks.live.cli import add_live_parser

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
        "--random", type=COUNT, metavar="N", help="evaluate every policy on N random groups of the test split"
    )
    cut = "with --random: cut every group to at most S simulated seconds (a quick look)"
    sync.add_argument("--max-duration", type=STEP, metavar="S", help=cut)
    sync.add_argument("--workers", type=COUNT, default=1, metavar="W", help="processes for --random (default 1)")
    batched = "with --random: run the policies that batch (mean, dqn_raw) and the runs without L2 on batched diagrams"
    sync.add_argument("--batch", action="store_true", help=batched)
    sync.add_argument(
        "--split",
        choices=("test", "validation", "train"),
        default="test",
        help="with --random: the split of the groups; choose settings on 'validation', report on 'test' (default)",
    )
    noisy = "with --random: groups with phase noise and frequency drift (the bound then knows the noise draw)"
    sync.add_argument("--noise", action="store_true", help=noisy)
    bound = sync.add_mutually_exclusive_group()
    bound.add_argument("--no-bound", action="store_true", help="with --random: skip the bound (fractions null)")
    bound.add_argument("--thorough-bound", action="store_true", help="with --random: a tighter bound, ~3x the CPU")
    sync.add_argument(
        "--policy",
        action="append",
        type=POLICY,
        metavar="NAME",
        help="motion computer(s) to run: dqn, dqn_raw, gated, lookahead, mean, mpc, plan, replan "
        "(default: dqn, lookahead, mean and pop_sync's default, gated; with --random every one listed); "
        "retired, with a warning: guard, pace; repeatable; "
        "with several, --plot FILE draws one figure per policy, FILE-<policy>",
    )
    blenders = "'continuous': the avatar never jumps; 'deliverable': the deliverable's, as in Table 3"
    sync.add_argument("--blender", choices=("continuous", "deliverable"), default="continuous", help=blenders)
    sync.add_argument(
        "--domain",
        choices=("phase", "position"),
        default="phase",
        help="'position': the L2 works on phases estimated from simulated arm positions (default 'phase')",
    )
    sync.add_argument(
        "--no-handover",
        dest="handover",
        action="store_false",
        help="with --domain position: draw the avatar from θ_L2 from the first tick, not the person's own movement "
        "until the phase estimate has settled",
    )
    sync.add_argument(
        "--duration", type=DURATION, metavar="SECONDS", help="simulated seconds (default: the group's, Table 2)"
    )
    sync.add_argument(
        "--seed",
        type=SEED,
        default=0,
        help="seed of the random groups with --random, of the arm positions' sensor noise with --domain position "
        "(default 0)",
    )
    _common(sync, trace=True)
    sync.set_defaults(handler=_run_sync)

    phase3d = targets.add_parser("phase3d", help="3D phase estimation accuracy and the 3D phase chain")
    phase3d.add_argument("--trajectories", type=COUNT, default=30, help="synthetic trajectories (default 30)")
    phase3d.add_argument("--seed", type=SEED, default=0, help="seed of the trajectories (default 0)")
    phase3d.add_argument("--rate", type=float, default=100.0, help="sampling rate in Hz, 30-240 (default 100)")
    phase3d.add_argument(
        "--set",
        dest="motion_set",
        choices=("today", "harder"),
        default="today",
        help="trajectories: 'today' (the generator's defaults) or 'harder' (rotations to 180°, uneven speed, "
        "100-300 ms freezes, 10 %% drifts; docs/phase-estimation-3d.md)",
    )
    _common(phase3d)
    add_recording_options(phase3d, _run_phase3d)

    phase1d = targets.add_parser("phase1d", help="1D phase estimation over sensor rates, units, quantisation, noise")
    phase1d.add_argument("--signals", type=int, default=10, help="seeded signals per cell (default 10, at most 10)")
    phase1d.add_argument("--duration", type=float, default=40.0, help="seconds per signal (default 40)")
    phase1d.add_argument("--workers", type=int, default=2, help="processes sharing the grid (default 2)")
    _common(phase1d)
    phase1d.set_defaults(handler=_run_phase1d)

    add_amplification_parser(targets, _common)

    demo = targets.add_parser("demo", help="a Kuramoto group (Table 2, group 3) without L2")
    demo.add_argument(
        "--duration", type=DURATION, default=300.0, metavar="SECONDS", help="simulated seconds (default 300)"
    )
    _common(demo, trace=True)
    demo.set_defaults(handler=_run_demo)
    add_sweep_parser(commands)
    add_analyse_parser(commands)
    add_live_parser(commands)
    return parser


def _common(p: argparse.ArgumentParser, trace: bool = False) -> None:
    from cogblocks.cli_options import PLOT_PATH, TRACE_PATH

    p.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    p.add_argument(
        "--plot", type=PLOT_PATH, metavar="FILE", help="after the results, save a figure to FILE (png, pdf, svg, ...)"
    )
    if trace:
        p.add_argument(
            "--save-trace", type=TRACE_PATH, metavar="FILE", help="save the run's trace to FILE (.npz or .parquet)"
        )


def _version() -> str:
    from cogblocks import __version__

    return f"cogblocks {__version__}"


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``cogblocks`` command."""
    try:  # the command's modules load here: Ctrl-C while they do stops as cleanly as during a run
        parser = _build_parser()
        args = parser.parse_args(argv)  # every option is checked here, before any simulation
    except SystemExit as exit_:  # --help, --version, or a bad option (argparse printed why)
        return int(exit_.code or 0)
    except KeyboardInterrupt:
        print("cogblocks: interrupted by Ctrl-C before the command started", file=sys.stderr)
        return 130
    handler = getattr(args, "handler", None)
    if handler is None:
        parser.print_help()
        return 0 if args.command is None else 2
    previous = signal.signal(signal.SIGTERM, _on_sigterm) if _main_thread() else None
    try:
        return handler(args)
    except (ValueError, OSError) as exc:
        print(f"cogblocks: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as stop:  # Ctrl-C, or SIGTERM through _on_sigterm
        _stop_workers()
        by = "SIGTERM" if isinstance(stop, _Terminated) else "Ctrl-C"
        print(f"cogblocks: interrupted by {by}; the figures above are all that was computed", file=sys.stderr)
        return 143 if isinstance(stop, _Terminated) else 130
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


class _Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the program is so that it stops as cleanly as on Ctrl-C."""


def _on_sigterm(signum: int, frame: Any) -> None:
    raise _Terminated


def _main_thread() -> bool:
    import threading

    return threading.current_thread() is threading.main_thread()


def _stop_workers() -> None:
    """End joblib's loky worker processes: they outlive an interrupted parallel run otherwise."""
    loky = sys.modules.get("joblib.externals.loky.reusable_executor")
    executor = getattr(loky, "_executor", None)
    if executor is not None:
        executor.shutdown(wait=True, kill_workers=True)


if __name__ == "__main__":
    sys.exit(main())
