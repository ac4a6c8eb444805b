"""Candidate defaults for noisy groups, on validation groups only: short-horizon re-planning with frequency tracking.

python studies/noisy_candidates.py OUT.json --policies replan_h5f [--groups 16] [--max-duration 20] [--noise-free]

``replan_hHf``: :class:`~cogblocks.sync.RecedingPlanMotion` planning H s ahead (not to the trial's end), its identifier
tracking drifting frequencies (``KuramotoRLS(omega_forgetting=0.995)``, a memory of about 2 s on each ω);
``gated_hHf``: the same behind :class:`~cogblocks.sync.GatedMotion`; ``gated_dS``: ``replan`` behind the gate, deciding
first after S s.
"""

from __future__ import annotations

import argparse
import json
import re
import time

from cogblocks.diagrams.sync import MOTIONS
from cogblocks.evaluation.sync_heldout import heldout_table
from cogblocks.sync import GatedMotion, RecedingPlanMotion
from cogblocks.sync.identification import KuramotoRLS


def tracking_replan(group, horizon: float, forgetting: float | None):
    motion = RecedingPlanMotion(
        group.n, group.assisted, adjacency=group.graph, end=group.duration, horizon=horizon, compare=None
    )
    if forgetting is not None:  # the identifier's sums stay the block's declared state
        tracker = KuramotoRLS(motion.adjacency, omega_forgetting=forgetting)
        tracker.info, tracker.rhs = motion.info, motion.rhs
        motion.rls = tracker
    return motion


parser = argparse.ArgumentParser()
parser.add_argument("out")
parser.add_argument("--policies", nargs="+", default=["replan_h5f"])
parser.add_argument("--groups", type=int, default=16)
parser.add_argument("--max-duration", type=float, default=20.0)
parser.add_argument("--noise-free", action="store_true")
args = parser.parse_args()
for name in args.policies:
    found = re.fullmatch(r"(replan|gated)_h(\d+)(f?)", name)
    if found:
        kind, horizon, tracks = found.group(1), float(found.group(2)), found.group(3) == "f"
        forgetting = 0.995 if tracks else None

        def build(g, horizon=horizon, forgetting=forgetting, kind=kind):
            motion = tracking_replan(g, horizon, forgetting)
            return GatedMotion(motion) if kind == "gated" else motion

        MOTIONS[name] = build
    found = re.fullmatch(r"gated_d([\d.]+)", name)
    if found:  # replan behind the gate, deciding first after the given seconds
        after = float(found.group(1))
        MOTIONS[name] = lambda g, after=after: GatedMotion(MOTIONS["replan"](g), decide_after=after)
start = time.process_time()
table = heldout_table(
    args.groups,
    0,
    args.policies,
    details=True,
    max_duration=args.max_duration,
    split="validation",
    bound=False,
    noise=not args.noise_free,
)
table["cpu_s"] = time.process_time() - start
table["argv"] = vars(args)
with open(args.out, "w") as f:
    json.dump(table, f)
print(json.dumps({k: table[k] for k in ("n_groups", "policies", "cpu_s")}))
