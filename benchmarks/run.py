"""Run the benchmarks; print one JSON object per line.

    python benchmarks/run.py [--quick] [--only NAME]

Each line is ``{"name", "value", "unit", "reference", "ratio"}`` (plus context
keys), where ``ratio = value / reference`` and the reference is measured in the
same run, so the ratios hold on a noisy shared machine. ``--only`` keeps the
benchmarks whose name starts with NAME (``engine``, ``engine.kuramoto.one_block``).
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

# name prefix of each module's results, where it differs from the module name
_PREFIXES = {
    "benchmarks.phase3d_latency": "phase3d",
    "benchmarks.l1_delay": "l1",
    "benchmarks.phase1d_accuracy": "phase1d",
}

# benchmark modules, in the order they run; each has run(quick) -> iterator of dicts
MODULES = [
    "benchmarks.engine",
    "benchmarks.sync",
    "benchmarks.scaling",
    "benchmarks.phase3d_latency",
    "benchmarks.l1_delay",
    "benchmarks.phase1d_accuracy",
    "benchmarks.amplification",
    "benchmarks.optimal_blending",
    "benchmarks.mpc",
    "benchmarks.bound",
    "benchmarks.plan",
    "benchmarks.replan",
    "benchmarks.planner",
    "benchmarks.pace",
    "benchmarks.guard",
    "benchmarks.soak",
    "benchmarks.sweep",
    "benchmarks.live",
    "benchmarks.scope",
    "benchmarks.loaders",
    "benchmarks.batch",
]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="short workloads, for a smoke test")
    parser.add_argument("--only", metavar="NAME", help="run only benchmarks whose name starts with NAME")
    args = parser.parse_args(argv)
    ran = 0
    for module_name in MODULES:
        prefix = _PREFIXES.get(module_name, module_name.split(".")[-1])
        if args.only and not (
            args.only == prefix or args.only.startswith(prefix + ".") or prefix.startswith(args.only)
        ):
            continue
        module = importlib.import_module(module_name)
        for result in module.run(quick=args.quick):
            if args.only and not result["name"].startswith(args.only):
                continue
            print(json.dumps(result), flush=True)
            ran += 1
    if ran == 0:
        print(f"no benchmark matches {args.only!r}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
