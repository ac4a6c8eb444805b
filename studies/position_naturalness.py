"""Where the avatar's peak speed comes from in the position domain: the phase estimate, or the alteration.

In ``pop_sync(..., domain="position", handover=False)`` the avatar's arm is ``150 mm · cos θ_L2`` with
``θ_L2 = θ̂_L0 + a``: the assisted person's phase as estimated from the arm positions, plus the blender's alteration
``a``; with the hand-over (the default) the avatar shows the person's own movement until the estimate has
settled (:class:`~cogblocks.sync.handover.SettledHandover`). For each group
this runs the closed loop once (the circular mean as motion computer: the alteration is small and follows the
group) and prints, as one JSON line per group and start tick, the peak speed over the person's true arm of

* ``estimate_alone``: the arm drawn from the estimated phase, ``150 · cos θ̂_L0`` (what the avatar shows with
  no alteration at all);
* ``avatar``: the avatar's arm, ``150 · cos θ_avatar`` (θ_L2 without the hand-over);

from tick ``--from-tick`` on (repeatable; 0 is the whole trial, as the naturalness figures count it), and the
run's ``change_pct`` (time-averaged r against the group without L2). ``--slew`` replaces the continuous
blender's slew limit (rad/s), to see what a slower alteration buys and costs; ``--no-handover`` draws the avatar
from θ_L2 from the start.

    python -m studies.position_naturalness --group 1 --group 2 --group 3 --from-tick 0 --from-tick 300 --no-handover
    python -m studies.position_naturalness --group 3 --motion dqn --slew 2 --from-tick 300
"""

from __future__ import annotations

import argparse
import dataclasses
import json

import numpy as np

from cogblocks.data.groups import TABLE2
from cogblocks.diagrams.sync import pop_sync, simulate
from cogblocks.sync.blending import CONTINUOUS

AMPLITUDE = 150.0  # mm, the arm of pop_sync's position domain


def peak_speed_ratio(arm: np.ndarray, person: np.ndarray, start: int) -> float:
    """Largest per-tick change of ``arm`` over the person's, from tick ``start`` on."""
    return float(np.abs(np.diff(arm[start:])).max() / np.abs(np.diff(person[start:])).max())


def breakdown(
    number: int, starts: list[int], motion: str = "mean", slew: float = CONTINUOUS.slew, handover: bool = True
) -> list[dict]:
    """The two peak speed ratios of Table 2's group ``number``, one row per start tick, and the run's gain in r."""
    group = TABLE2[number]
    n_steps = round(group.duration / 0.01) + 1
    blender = dataclasses.replace(CONTINUOUS, slew=slew)
    diagram = pop_sync(group, motion=motion, blender=blender, domain="position", handover=handover)
    shown = "avatar.theta_avatar" if handover else "l2.theta_l2"
    probes = {"avatar": shown, "theta_l0": "l2.theta_l0", "theta": "group.theta"}
    trace = simulate(diagram, n_steps, probes, label=f"group {number}", progress=False)
    without = simulate(pop_sync(group, l2=False), n_steps, label=f"group {number} without L2", progress=False)
    change_pct = 100.0 * (float(np.mean(trace["r"])) / float(np.mean(without["r"])) - 1.0)
    person = AMPLITUDE * np.cos(np.asarray(trace["theta"])[:, group.assisted])
    estimate = AMPLITUDE * np.cos(np.asarray(trace["theta_l0"]))
    avatar = AMPLITUDE * np.cos(np.asarray(trace["avatar"]))
    return [
        {
            "group": number,
            "motion": motion,
            "slew": slew,
            "handover": handover,
            "change_pct": change_pct,
            "from_tick": start,
            "estimate_alone": peak_speed_ratio(estimate, person, start),
            "avatar": peak_speed_ratio(avatar, person, start),
        }
        for start in starts
    ]


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--group", type=int, action="append", choices=sorted(TABLE2), help="Table 2's group")
    parser.add_argument("--from-tick", type=int, action="append", help="first tick counted (default 0 and 300)")
    parser.add_argument("--motion", default="mean", help="motion computer (default: the circular mean)")
    parser.add_argument("--slew", type=float, default=CONTINUOUS.slew, help="the blender's slew limit, rad/s")
    parser.add_argument("--no-handover", dest="handover", action="store_false", help="the avatar is θ_L2 throughout")
    args = parser.parse_args(argv)
    for number in args.group or sorted(TABLE2):
        for row in breakdown(number, args.from_tick or [0, 300], args.motion, args.slew, args.handover):
            print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
