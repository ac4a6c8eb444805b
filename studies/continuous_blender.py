"""How the continuous blender's slew limit trades the avatar's jumps against the gain in r.

For every group, motion computer and blender, the closed loop of ``pop_sync`` is run and three figures are
printed as one JSON line: ``change_pct`` (time-averaged r against the group without L2), ``max_step_rad`` (the
largest per-tick change of wrap_π(θ_L2 − θ_L0)) and ``jumps`` (ticks where that change exceeds 0.05 rad, the
avatar running more than 5 rad/s off the person's pace).

    python studies/continuous_blender.py --split validation --groups 5 --max-duration 30 --policy replan \
        --slew 2 --slew 3 --slew 4

chooses the slew limit on validation groups; ``--table2 N`` (repeatable) runs Table 2's group N instead.
"""

from __future__ import annotations

import argparse
import dataclasses
import json

import numpy as np

from cogblocks.data.groups import TABLE2, random_groups
from cogblocks.diagrams.sync import pop_sync, simulate
from cogblocks.sync.blending import CONTINUOUS, DELIVERABLE

JUMP = 0.05  # rad per 10 ms tick


def measure(group, policy: str, blender, r_without: float) -> dict:
    n = round(group.duration / 0.01) + 1
    probes = {"l2": "l2.theta_l2", "l0": "l2.theta_l0"}
    trace = simulate(pop_sync(group, motion=policy, blender=blender), n, probes, label=policy, progress=False)
    shift = np.angle(np.exp(1j * (trace["l2"] - trace["l0"])))
    step = np.abs(np.angle(np.exp(1j * np.diff(shift))))
    r = float(trace["r"].mean())
    return {
        "change_pct": 100.0 * (r - r_without) / r_without,
        "max_step_rad": float(step.max()),
        "jumps": int((step > JUMP).sum()),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--split", default="validation", choices=("validation", "train"))
    parser.add_argument("--groups", type=int, default=5)
    parser.add_argument("--table2", type=int, action="append", help="Table 2's group N instead of the split's")
    parser.add_argument("--max-duration", type=float, default=None)
    parser.add_argument("--policy", action="append", required=True)
    parser.add_argument("--slew", action="append", type=float, default=[], help="(default: CONTINUOUS's)")
    parser.add_argument("--no-deliverable", dest="deliverable", action="store_false", help="skip the deliverable's")
    args = parser.parse_args()
    groups = (
        {str(k): TABLE2[k] for k in args.table2}
        if args.table2
        else {f"{args.split}{i}": g for i, g in enumerate(random_groups(600, args.split, 0)[: args.groups])}
    )
    blenders = {"deliverable": DELIVERABLE} if args.deliverable else {}
    blenders.update(
        {f"slew{s:g}": dataclasses.replace(CONTINUOUS, slew=s) for s in args.slew} or {"continuous": CONTINUOUS}
    )
    for name, group in groups.items():
        if args.max_duration is not None:
            group = dataclasses.replace(group, duration=min(group.duration, args.max_duration))
        n = round(group.duration / 0.01) + 1
        r_without = float(simulate(pop_sync(group, l2=False), n, label="none", progress=False)["r"].mean())
        for policy in args.policy:
            for label, blender in blenders.items():
                row = {"group": name, "duration": group.duration, "policy": policy, "blender": label}
                print(json.dumps({**row, **measure(group, policy, blender, r_without)}), flush=True)


if __name__ == "__main__":
    main()
