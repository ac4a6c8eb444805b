"""``cogblocks run sync --random N``: the held-out table, each group reported on stderr as it is done.

A long table is interrupted more often than it finishes: every finished group is printed the moment it
is known, and an interrupted run prints the table of the groups it finished (``"interrupted": true``)
before the command stops.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from cogblocks.cli_options import plot_output, print_result

__all__ = ["group_line", "run_sync_heldout"]


def group_line(done: int, total: int, row: dict[str, Any]) -> str:
    """One finished group as a progress line: its name, r without L2 and each policy's change."""
    changes = ", ".join(f"{r['policy']} {r['change_pct']:+.2f} %" for r in row["results"])
    return (
        f"group {done}/{total} done: {row['name']}, {row['n']} members: r without L2 {row['r_without']:.4f}; {changes}"
    )


def run_sync_heldout(args: argparse.Namespace, motions: list[str]) -> int:
    """Run the held-out table the options ask for and print it (text or ``--json``); ``--plot`` draws it."""
    from cogblocks.diagrams.sync import DEFAULT_MOTION
    from cogblocks.evaluation.sync_heldout import heldout_table, plot_heldout, summarise

    if args.duration is not None or args.save_trace:
        raise ValueError("--random evaluates each group over its own duration: drop --duration and --save-trace")
    finished: dict[int, dict[str, Any]] = {}

    def progress(index: int, row: dict[str, Any]) -> None:
        finished[index] = row
        print(group_line(len(finished), args.random, row), file=sys.stderr, flush=True)

    options = {"max_duration": args.max_duration, "split": args.split, "thorough": args.thorough_bound}
    try:
        result = heldout_table(
            args.random,
            args.seed,
            motions,
            workers=args.workers,
            blender=args.blender,
            details=bool(args.plot),
            bound=not args.no_bound,
            noise=args.noise,
            domain=args.domain,
            handover=args.handover,
            progress=progress,
            batch=args.batch,
            **options,
        )
    except KeyboardInterrupt:
        if finished:  # the table of the groups done, so that none of them is lost
            rows = [finished[i] for i in sorted(finished)]
            partial = {"n_groups": len(rows), "seed": args.seed, "policies": summarise(rows, motions)}
            partial.update(interrupted=True, n_requested=args.random, groups_done=sorted(finished))
            print_result(partial, args.json, lambda r: _render(r, args, DEFAULT_MOTION))
        raise
    groups = result.pop("groups", None)
    print_result(result, args.json, lambda r: _render(r, args, DEFAULT_MOTION))
    plot_output(args.plot, lambda path: plot_heldout({**result, "groups": groups}, path))
    return 0


def _render(r: dict[str, Any], args: argparse.Namespace, default_motion: str) -> str:
    held = ("held-out " if args.split == "test" else "") + ("noisy " if args.noise else "")
    count = f"{r['n_groups']} of {r['n_requested']}" if r.get("interrupted") else f"{r['n_groups']}"
    lines = [
        f"{count} {held}random groups ({args.split} split, seed {r['seed']}): change of the mean order "
        f"parameter with L2 (pop_sync's default policy: {default_motion})",
        f"  {'policy':>10}  lowered  mean %   p5 %  worst %  of bound |θ_L2 − θ_L0| rad  max step  jumps/min speed",
    ]
    for row in r["policies"]:
        bound = "–" if row["mean_bound_fraction"] is None else f"{row['mean_bound_fraction']:.2f}"
        lines.append(
            f"  {row['policy']:>10}  {100 * row['lowered_share']:5.1f} %  {row['mean_change_pct']:+6.2f} "
            f"{row['p5_change_pct']:+6.2f}  {row['worst_change_pct']:+7.2f}  {bound:>8}  "
            f"{row['mean_dev_rad']:.3f} / {row['max_dev_rad']:.3f}    {row['max_step_rad']:.3f} rad  "
            f"{row['mean_jumps_per_min']:9.1f}  {row['max_peak_speed_ratio']:4.1f}x"
        )
    return "\n".join(lines)
