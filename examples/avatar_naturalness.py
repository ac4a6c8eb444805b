"""How natural is the avatar? θ_L2 − θ_L0 and the avatar's phase speed on Table 2's group 3, for one blender.

    python examples/avatar_naturalness.py [FOLDER] [--blender SPEC] [--duration S] [--motions mean,dqn,replan]

SPEC is ``deliverable`` (the deliverable's blender, the default), a word ``pop_sync`` understands, or
``NAME=MODULE:CALLABLE[:JSON]`` (see ``python -m cogblocks.experiments.sync_naturalness --help``). The figure
``avatar-naturalness-NAME.png`` goes to FOLDER (the working directory by default); the metrics of
:mod:`cogblocks.diagrams.naturalness` are printed per motion computer.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from cogblocks.data.groups import TABLE2
from cogblocks.diagrams.naturalness import JUMP_RAD, alteration_steps, phase_naturalness, phase_speed
from cogblocks.diagrams.sync import pop_sync, simulate
from cogblocks.experiments.sync_naturalness import blender_from_spec

parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
parser.add_argument("folder", nargs="?", default=".")
parser.add_argument("--blender", default="deliverable")
parser.add_argument("--duration", type=float, default=10.0, help="seconds of group 3 (the docs' figure: 60)")
parser.add_argument("--motions", default="mean,replan", help="comma-separated motion computers")
args = parser.parse_args()

name, _ = blender_from_spec(args.blender)
group = dataclasses.replace(TABLE2[3], duration=args.duration)
motions = [m for m in args.motions.split(",") if m]
n_steps = round(group.duration / 0.01) + 1
fig, axes = plt.subplots(len(motions), 2, figsize=(11, 2.6 * len(motions)), squeeze=False, sharex=True)
for row, motion in zip(axes, motions, strict=True):
    _, blender = blender_from_spec(args.blender)
    probes = {"theta_l2": "l2.theta_l2", "theta_l0": "l2.theta_l0"}
    trace = simulate(pop_sync(group, motion=motion, blender=blender), n_steps, probes, label=motion)
    figures = phase_naturalness(trace["theta_l2"], trace["theta_l0"])
    print(f"{motion}: " + ", ".join(f"{key} {value:.3f}" for key, value in figures.items()))
    t = trace.t
    alteration = np.mod(trace["theta_l2"] - trace["theta_l0"] + np.pi, 2 * np.pi) - np.pi
    jumps = np.flatnonzero(alteration_steps(trace["theta_l2"], trace["theta_l0"]) > JUMP_RAD) + 1
    row[0].plot(t, alteration, color="tab:blue", lw=0.8)
    row[0].plot(t[jumps], alteration[jumps], "r.", ms=3, label=f"change > {JUMP_RAD} rad in one tick")
    row[0].set_ylabel(f"{motion}\nθ_L2 − θ_L0 [rad]")
    row[0].legend(loc="upper right", fontsize=7)
    row[1].plot(t[1:], phase_speed(trace["theta_l2"]), color="tab:blue", lw=0.8, label="avatar")
    row[1].plot(t[1:], phase_speed(trace["theta_l0"]), color="k", lw=0.8, label="person")
    row[1].set_ylabel("phase speed [rad/s]")
    row[1].set_title(
        f"max step {figures['max_step_rad']:.2f} rad, {figures['jumps_per_min']:.0f} jumps/min, "
        f"peak speed {figures['peak_speed_ratio']:.1f}× the person's",
        fontsize=8,
    )
    row[1].legend(loc="upper right", fontsize=7)
for ax in axes[-1]:
    ax.set_xlabel("t [s]")
fig.suptitle(f"Table 2 group 3, first {args.duration:g} s, blender: {name}", fontsize=10)
fig.tight_layout()
path = Path(args.folder) / f"avatar-naturalness-{name}.png"
fig.savefig(path, dpi=110)
print(f"wrote {path}")
