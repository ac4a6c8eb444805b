"""``cogblocks live sync|phase|l1``: run a ready diagram on real LSL streams in real time."""

from __future__ import annotations

import argparse
import json
from typing import Any

from cogblocks.cli_options import POLICY, STEP

__all__ = ["add_live_parser"]

DT = 0.01  # 100 Hz


def _run_live(args: argparse.Namespace) -> int:
    try:
        from cogblocks.live.ready import LIVE_DIAGRAMS
        from cogblocks.live.runner import run_realtime
    except ImportError as exc:
        raise ValueError(f'cogblocks live needs the live extra: pip install -e ".[live]" ({exc})') from None

    options: dict[str, Any] = {"timeout": args.timeout}
    if args.diagram == "sync":
        options.update(group=args.group, motion=args.policy, blender=args.blender)
    elif args.diagram == "l1":
        options.update(delay=args.delay)
    try:
        compiled = LIVE_DIAGRAMS[args.diagram](args.in_stream, args.out_stream, **options).compile(DT)
    except KeyboardInterrupt:
        return 130
    try:
        report = run_realtime(
            compiled, args.duration, 1.0 / DT, record=bool(args.save), record_raw=bool(args.save), save=args.save
        )
    finally:
        for block in compiled.blocks.values():
            if hasattr(block, "close"):
                block.close()
    result = report.summary()
    if args.json:
        print(json.dumps(result))
    else:
        stopped = " (stopped by Ctrl-C)" if report.interrupted else ""
        print(
            f"{args.diagram} live, {args.in_stream!r} -> {args.out_stream!r}: {result['ticks']} ticks at 100 Hz"
            f"{stopped}, {result['late_ticks']} late; tick p50 {result['tick_ms_p50']:.2f} ms, "
            f"p99 {result['tick_ms_p99']:.2f} ms; {result['samples_in']} samples in, {result['samples_out']} out; "
            f"oldest sample used {result['max_age_ms']:.1f} ms"
        )
        if args.save:
            print(f"saved the trace and the raw samples to {args.save}")
    return 0


def add_live_parser(commands: argparse._SubParsersAction) -> None:
    """Add the ``live`` command to the ``cogblocks`` command line's sub-commands."""
    live = commands.add_parser("live", help="run a ready diagram on real LSL streams in real time (100 Hz)")
    diagrams = live.add_subparsers(dest="diagram", metavar="DIAGRAM")
    live.set_defaults(handler=lambda _: live.print_help() or 2)
    helps = {
        "phase": "a 1-channel position stream (mm) in, its estimated phase (rad) out",
        "sync": "the participants' phases (rad, one channel each) in, the avatar's phase θ_L2 out",
        "l1": "a 3-channel marker stream (mm) in, the L1 avatar's delay-compensated position out",
    }
    for name, text in helps.items():
        p = diagrams.add_parser(name, help=text, description=text)
        p.add_argument("--in", dest="in_stream", required=True, metavar="STREAM", help="name of the input stream")
        p.add_argument("--out", dest="out_stream", required=True, metavar="STREAM", help="name of the output stream")
        p.add_argument("--duration", type=STEP, required=True, metavar="S", help="seconds to run (Ctrl-C stops)")
        p.add_argument("--timeout", type=STEP, default=5.0, metavar="S", help="seconds to wait for the input stream")
        p.add_argument("--json", action="store_true", help="print one JSON object instead of text")
        p.add_argument("--save", metavar="FILE", help="save the trace and the raw input samples to FILE (.npz)")
        if name == "sync":
            p.add_argument("--group", type=int, choices=(1, 2, 3), default=1, help="Table 2's group (default 1)")
            p.add_argument(
                "--policy",
                type=POLICY,
                default="dqn",
                help="motion computer, e.g. dqn, lookahead or mean (default dqn)",
            )
            p.add_argument(
                "--blender",
                choices=("continuous", "deliverable"),
                default="continuous",
                help="'continuous': the avatar never jumps; 'deliverable': the deliverable's exact blender "
                "(default 'continuous')",
            )
        if name == "l1":
            p.add_argument("--delay", type=float, default=0.1, help="delay to compensate, seconds (default 0.1)")
        p.set_defaults(handler=_run_live)
