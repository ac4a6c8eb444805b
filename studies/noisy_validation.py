"""Validation runs of the noisy groups (never the test split): one JSON file per call, rows per group.

python studies/noisy_validation.py OUT.json --policies replan mean dqn guard [--bound [--thorough]] [--noise-free]
    [--domain position [--no-handover]] [--groups 16] [--max-duration 60] [--blender continuous]
"""

from __future__ import annotations

import argparse
import json
import time

from cogblocks.evaluation.sync_heldout import heldout_table

parser = argparse.ArgumentParser()
parser.add_argument("out")
parser.add_argument("--policies", nargs="+", default=["mean"])
parser.add_argument("--bound", action="store_true")
parser.add_argument("--thorough", action="store_true", help="the thorough bound (about 3x the CPU)")
parser.add_argument("--noise-free", action="store_true")
parser.add_argument("--domain", default="phase")
parser.add_argument("--groups", type=int, default=16)
parser.add_argument("--max-duration", type=float, default=60.0)
parser.add_argument("--blender", default="continuous")
parser.add_argument("--no-handover", dest="handover", action="store_false", help="position domain: avatar from θ_L2")
args = parser.parse_args()
start = time.process_time()
table = heldout_table(
    args.groups,
    0,
    args.policies,
    details=True,
    max_duration=args.max_duration,
    split="validation",
    bound=args.bound,
    thorough=args.thorough,
    noise=not args.noise_free,
    domain=args.domain,
    handover=args.handover,
    blender=args.blender,
)
table["cpu_s"] = time.process_time() - start
table["argv"] = vars(args)
with open(args.out, "w") as f:
    json.dump(table, f)
print(json.dumps({k: table[k] for k in ("n_groups", "policies", "cpu_s")}))
