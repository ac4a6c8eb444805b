"""The validation table of docs/explanation/noisy-groups.md from studies/noisy_validation.py's JSON files.

python studies/noisy_table.py BOUND.json OTHER.json ...   (BOUND.json: a run with --bound)
"""

from __future__ import annotations

import json
import sys

import numpy as np

bound_run, *others = (json.load(open(path)) for path in sys.argv[1:])
rows = bound_run["groups"]
r_bound = np.array([row["r_bound"] for row in rows])
r_without = np.array([row["r_without"] for row in rows])
changes: dict[str, np.ndarray] = {}
fractions: dict[str, float] = {}
for run in (bound_run, *others):
    assert np.allclose([row["r_without"] for row in run["groups"]], r_without, rtol=0, atol=1e-15)
    for policy in [p["policy"] for p in run["policies"]]:
        r_with = np.array([next(r for r in row["results"] if r["policy"] == policy)["r_with"] for row in run["groups"]])
        changes[policy] = 100.0 * (r_with - r_without) / r_without
        headroom = r_bound - r_without
        keep = headroom > 1e-3
        fractions[policy] = float(np.mean((r_with - r_without)[keep] / headroom[keep]))
bound_change = 100.0 * (r_bound - r_without) / r_without
mean_gain = changes["mean"].mean()
with_headroom = int((r_bound - r_without > 1e-3).sum())
print(f"clairvoyant bound: mean change {bound_change.mean():+.2f} %, groups with headroom {with_headroom}")
print(
    "| motion computer | groups where r is lowered | mean change | worst | × the circular mean's gain "
    "| of the clairvoyant bound |"
)
print("|---|---|---|---|---|---|")
for policy, change in changes.items():
    print(
        f"| {policy} | {(change < 0).sum()} / {len(change)} | {change.mean():+.2f} % | {change.min():+.2f} % | "
        f"{change.mean() / mean_gain:.2f} | {fractions[policy]:.2f} |"
    )
bound_ratio = bound_change.mean() / mean_gain
print(f"| clairvoyant bound | – | {bound_change.mean():+.2f} % | {bound_change.min():+.2f} % | {bound_ratio:.2f} | 1 |")
