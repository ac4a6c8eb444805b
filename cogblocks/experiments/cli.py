"""``cogblocks sweep``: the group comparison of the PoP of Social Connectedness as a sweep, laptop to cluster."""

from __future__ import annotations

import argparse
import json
from typing import Any

from cogblocks.cli_options import COUNT, SEED, output_type, write_safely

__all__ = ["add_sweep_parser"]


def _int_list(text: str) -> list[int]:
    try:
        return [int(part) for part in text.split(",") if part]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated integers, got {text!r}") from None


def _name_list(text: str) -> list[str]:
    return [part.strip() for part in text.split(",") if part.strip()]


def add_sweep_parser(commands: Any) -> None:
    """Add ``sweep sync`` to the ``cogblocks`` command's subparsers."""
    sweep = commands.add_parser("sweep", help="run a ready comparison as a parameter sweep (loky or Dask)")
    targets = sweep.add_subparsers(dest="target", metavar="TARGET")
    sweep.set_defaults(handler=lambda _: sweep.print_help() or 2)
    sync = targets.add_parser(
        "sync", help="PoP of Social Connectedness: groups × motion computers, with and without L2"
    )
    sync.add_argument(
        "--groups", type=_int_list, default=None, help="Table 2's groups, e.g. 1,2,3 (default: all, unless --random)"
    )
    sync.add_argument("--random", type=COUNT, metavar="N", help="also N held-out random groups (random_groups)")
    sync.add_argument("--split", default="test", help="split of the random groups (default 'test')")
    sync.add_argument("--group-seed", type=SEED, default=0, help="seed of the random groups (default 0)")
    sync.add_argument(
        "--policies", type=_name_list, default=["mean", "lookahead", "dqn"], help="motion computers (default all)"
    )
    sync.add_argument("--domain", choices=("phase", "position"), default="phase", help="see `run sync --domain`")
    sync.add_argument("--seeds", type=COUNT, default=1, help="replicates per run (position domain noise; default 1)")
    sync.add_argument("--backend", choices=("loky", "dask", "serial"), default="loky", help="default loky")
    sync.add_argument("--workers", type=COUNT, default=None, help="workers (default: all cores)")
    sync.add_argument("--scheduler", metavar="ADDRESS", help="a dask scheduler address (default: a local cluster)")
    sync.add_argument(
        "--out",
        type=output_type((".parquet", ".csv")),
        metavar="FILE",
        help="write every run to FILE (.parquet or .csv)",
    )
    sync.add_argument("--json", action="store_true", help="print the summary as JSON")
    batched = "run the runs without L2 and the policies that batch (mean, dqn_raw) on batched diagrams (phase domain)"
    sync.add_argument("--batch", action="store_true", help=batched)
    sync.set_defaults(handler=_sweep_sync)


def _sweep_sync(args: argparse.Namespace) -> int:
    from cogblocks.experiments.sweep import save_results
    from cogblocks.experiments.sync import random_group_set, sweep_sync, table2_groups

    if args.scheduler and args.backend != "dask":
        raise ValueError("--scheduler needs --backend dask")
    groups = table2_groups(args.groups or ([] if args.random else [1, 2, 3]))
    if args.random:
        groups.update(random_group_set(args.random, split=args.split, seed=args.group_seed))
    df = sweep_sync(
        groups,
        args.policies,
        domain=args.domain,
        seeds=args.seeds,
        backend=args.backend,
        n_jobs=args.workers,
        client=args.scheduler,
        batch=args.batch,
    )
    if args.out:
        write_safely(args.out, lambda path: save_results(df, path), "the sweep's results")
    summary = df.groupby(["group", "policy"], sort=False)[["r_mean", "change_pct"]].mean().reset_index()
    failed = int(df["error"].notna().sum())
    if args.json:
        print(json.dumps({"runs": len(df), "failed": failed, "summary": summary.to_dict(orient="records")}))
        return 0 if failed == 0 else 1
    print(f"{len(df)} runs ({failed} failed) on {args.backend}; time-averaged order parameter r (mean over seeds):")
    for row in summary.itertuples():
        change = "" if row.policy == "none" else f" ({row.change_pct:+.2f} %)"
        print(f"  group {row.group:>6}  {row.policy:>10}: r {row.r_mean:.4f}{change}")
    if args.random:
        random = df[~df["group"].isin([str(n) for n in (args.groups or [])])]
        by_policy = random.groupby("policy", sort=False)["change_pct"].agg(["mean", "std"])
        print(f"held-out random groups ({args.random}, split {args.split!r}): change of r, mean ± std")
        for policy, row in by_policy.iterrows():
            if policy != "none":
                print(f"  {policy:>10}: {row['mean']:+.2f} ± {row['std']:.2f} %")
    return 0 if failed == 0 else 1
