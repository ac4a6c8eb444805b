"""Gain and naturalness of every motion computer with each blender, on held-out random groups and Table 2's.

Usage::

    python -m cogblocks.experiments.sync_naturalness --random 200 [--split test] [--seed 0] [--table2]
        [--blender NAME=MODULE:CALLABLE[:JSON] | --blender WORD ...] [--policy NAME ...] [--max-duration S]
        [--workers W] [--json]

Each group runs once without L2, then once per blender and motion computer in
:func:`~cogblocks.diagrams.sync.pop_sync` (``blender=`` the blender built from its spec: ``MODULE:CALLABLE``
called with the JSON object's keywords, or a bare word handed to ``pop_sync`` as it is). Per blender and motion
computer the summary gives the share of groups lowered, the mean and worst change of r, the mean change as a
fraction of the first blender's (``gain_kept``), and the naturalness figures of
:mod:`cogblocks.diagrams.naturalness`: the largest per-tick change of wrap(θ_L2 − θ_L0) on any group, the share of
groups without a jump, the mean jumps per minute and the largest peak phase speed ratio.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import json
import sys
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from cogblocks.data.groups import TABLE2, SyncGroup, random_groups
from cogblocks.diagrams.naturalness import sync_naturalness
from cogblocks.diagrams.sync import DEFAULT_MOTION, MOTIONS, pop_sync, simulate
from cogblocks.evaluation.sync_heldout import each_group
from cogblocks.sim.timing import BASE_STEP

__all__ = ["blender_from_spec", "compare_blenders", "evaluate_group", "main", "summarise"]

_PROBES = {"theta_l2": "l2.theta_l2", "theta_l0": "l2.theta_l0"}


def blender_from_spec(spec: str) -> tuple[str, Any]:
    """``"NAME=MODULE:CALLABLE[:JSON]"`` → (NAME, the callable's result with the JSON object as keywords).

    A spec without ``=`` is a word ``pop_sync`` understands itself (returned as ``(word, word)``); ``"deliverable"``
    is the deliverable's blender, ``pop_sync``'s ``blender=None``.
    """
    if "=" not in spec:
        return spec, (None if spec == "deliverable" else spec)
    name, _, target = spec.partition("=")
    module, _, rest = target.partition(":")
    attr, _, options = rest.partition(":")
    if not name or not module or not attr:
        raise ValueError(f"--blender: expected NAME=MODULE:CALLABLE[:JSON] or a word, got {spec!r}")
    try:
        factory = getattr(importlib.import_module(module), attr)
    except (ImportError, AttributeError) as error:
        raise ValueError(f"--blender {spec!r}: cannot find {module}:{attr} ({error})") from None
    kwargs = json.loads(options) if options else {}
    if not isinstance(kwargs, dict):
        raise ValueError(f"--blender {spec!r}: the options must be a JSON object, got {options!r}")
    return name, factory(**kwargs)


def evaluate_group(group: SyncGroup, policies: Sequence[str], blenders: Sequence[str]) -> dict[str, Any]:
    """One group: r without L2, and per blender spec and policy r with L2, its change (%) and the naturalness."""
    n_steps = round(group.duration / BASE_STEP) + 1
    r_without = float(simulate(pop_sync(group, l2=False), n_steps, label=group.name)["r"].mean())
    rows = []
    for spec in blenders:
        name, _ = blender_from_spec(spec)
        for policy in policies:
            _, blender = blender_from_spec(spec)  # a fresh blender per run: blocks keep state
            diagram = pop_sync(group, motion=policy, blender=blender)
            trace = simulate(diagram, n_steps, _PROBES, label=f"{group.name}, {name}, {policy}")
            r_with = float(trace["r"].mean())
            change = 100.0 * (r_with - r_without) / r_without
            rows.append({"blender": name, "policy": policy, "r_with": r_with, "change_pct": change,
                         **sync_naturalness(trace)})  # fmt: skip
    return {"name": group.name, "r_without": r_without, "results": rows}


def summarise(groups: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per (blender, policy): gain figures, ``gain_kept`` against the first blender, and naturalness over groups."""
    pairs = list(dict.fromkeys((r["blender"], r["policy"]) for r in groups[0]["results"]))
    first = pairs[0][0]
    summary = []
    for blender, policy in pairs:

        def pick(b: str, key: str, policy: str = policy) -> np.ndarray:
            return np.array([next(r[key] for r in g["results"] if (r["blender"], r["policy"]) == (b, policy))
                             for g in groups])  # fmt: skip

        change, reference = pick(blender, "change_pct"), pick(first, "change_pct")
        jumps = pick(blender, "jumps_per_min")
        summary.append({
            "blender": blender, "policy": policy, "groups": len(groups),
            "lowered_share": float(np.mean(change < 0.0)), "mean_change_pct": float(change.mean()),
            "worst_change_pct": float(change.min()),
            "gain_kept": float(change.mean() / reference.mean()) if reference.mean() > 0 else None,
            "max_step_rad": float(pick(blender, "max_step_rad").max()), "jump_free_share": float(np.mean(jumps == 0)),
            "mean_jumps_per_min": float(jumps.mean()),
            "max_peak_speed_ratio": float(pick(blender, "peak_speed_ratio").max()),
        })  # fmt: skip
    return summary


def compare_blenders(
    groups: Sequence[SyncGroup],
    policies: Sequence[str],
    blenders: Sequence[str],
    *,
    workers: int = 1,
    max_duration: float | None = None,
    progress: Callable[[int, dict[str, Any]], None] | None = None,
) -> dict[str, Any]:
    """:func:`evaluate_group` on every group (joblib with ``workers`` > 1), then :func:`summarise`.

    Returns ``{"summary": [...], "groups": [...]}``; ``max_duration`` cuts every group (a quick check only).
    ``progress(index, row)`` is called as each group is done (with workers, in the order they finish), so that an
    interrupted caller keeps every group finished so far.
    """
    unknown = [name for name in policies if name not in MOTIONS]
    if unknown:
        raise ValueError(f"unknown policy {unknown[0]!r}: choose from {sorted(MOTIONS)}")
    for spec in blenders:
        blender_from_spec(spec)  # every spec checked before the first run
    if max_duration is not None:
        groups = [dataclasses.replace(g, duration=min(g.duration, max_duration)) for g in groups]
    rows = each_group(evaluate_group, [(g, policies, blenders) for g in groups], workers, progress)
    return {"summary": summarise(rows), "groups": rows}


def _group_line(done: int, total: int, row: dict[str, Any]) -> str:
    changes = ", ".join(f"{r['blender']} {r['policy']} {r['change_pct']:+.2f} %" for r in row["results"])
    return f"group {done}/{total} done: {row['name']}: r without L2 {row['r_without']:.4f}; {changes}"


def main(argv: Sequence[str] | None = None) -> int:
    """Command-line entry point: the summary as text, or with ``--json`` the summary and every group's rows."""
    parser = argparse.ArgumentParser(prog="python -m cogblocks.experiments.sync_naturalness", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    parser.add_argument("--random", type=int, default=0, metavar="N", help="N random groups of --split")
    parser.add_argument("--split", default="test", choices=("train", "validation", "test"))
    parser.add_argument("--seed", type=int, default=0, help="seed of the random groups (default 0)")
    parser.add_argument("--table2", action="store_true", help="also Table 2's groups 1, 2 and 3")
    parser.add_argument("--blender", action="append", default=None, help="a blender spec (repeatable; default: "
                        "the deliverable's); the first is the reference of gain_kept")  # fmt: skip
    parser.add_argument("--policy", action="append", default=None, help=f"default: every one of {sorted(MOTIONS)}")
    parser.add_argument("--max-duration", type=float, default=None, metavar="S", help="cut groups (a quick check)")
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    groups = random_groups(args.random, args.split, args.seed) if args.random else []
    if args.table2:
        groups += [dataclasses.replace(TABLE2[n], name=f"Table 2 group {n}") for n in sorted(TABLE2)]
    if not groups:
        parser.error("give --random N and/or --table2")
    policies = args.policy or list(MOTIONS)
    finished: dict[int, dict[str, Any]] = {}

    def progress(index: int, row: dict[str, Any]) -> None:
        finished[index] = row
        print(_group_line(len(finished), len(groups), row), file=sys.stderr, flush=True)

    try:
        result = compare_blenders(groups, policies, args.blender or ["deliverable"], workers=args.workers,
                                  max_duration=args.max_duration, progress=progress)  # fmt: skip
    except KeyboardInterrupt:
        print("interrupted by Ctrl-C", file=sys.stderr, flush=True)
        if not finished:
            return 130
        rows = [finished[i] for i in sorted(finished)]  # the groups done are summarised, none of them lost
        result = {"summary": summarise(rows), "groups": rows, "interrupted": True, "n_requested": len(groups)}
        code = 130
    else:
        code = 0
    if args.json:
        print(json.dumps(result), flush=True)
        return code
    if code:
        print(f"interrupted: the {len(result['groups'])} groups done of these", flush=True)
    print(f"{len(groups)} groups ({args.random} of the {args.split} split, seed {args.seed}"
          f"{', and Table 2' if args.table2 else ''}); pop_sync's default policy: {DEFAULT_MOTION}")  # fmt: skip
    print(
        f"  {'blender':>12} {'policy':>8}  lowered  mean %  worst %  gain kept  max step  jump-free  jumps/min  speed"
    )
    for s in result["summary"]:
        kept = "–" if s["gain_kept"] is None else f"{s['gain_kept']:.2f}"
        print(f"  {s['blender']:>12} {s['policy']:>8}  {100 * s['lowered_share']:5.1f} %  {s['mean_change_pct']:+6.2f} "
              f" {s['worst_change_pct']:+7.2f}  {kept:>9}  {s['max_step_rad']:8.3f}  "
              f"{100 * s['jump_free_share']:7.0f} %  {s['mean_jumps_per_min']:9.1f}  "
              f"{s['max_peak_speed_ratio']:5.1f}")  # fmt: skip
    return code


if __name__ == "__main__":
    raise SystemExit(main())
