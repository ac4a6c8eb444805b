"""Where the whole-run search of :mod:`cogblocks.analysis.sync_ocp` starts, and the rules it switches to.

Simple reference rules (doing nothing, the others' circular mean, constant frequencies), all simulated at once
on the exact NumPy model of the simulation, and the references that closed-loop policies (``pace``, ``guard``)
make on the group: the whole-run search is a local one, so what it starts from decides much of what it finds.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from cogblocks.data.groups import SyncGroup
from cogblocks.sim import Diagram, Simulator
from cogblocks.sync.blender import Blender
from cogblocks.sync.group import KuramotoGroup
from cogblocks.sync.guarded import GuardedPacingMotion
from cogblocks.sync.l2 import L2Sync
from cogblocks.sync.model import DT, BlenderParams
from cogblocks.sync.pacing import PacingMotion
from cogblocks.sync.whole_run import initial_state, rule_rollouts

__all__ = ["closed_loop_start", "policy_starts", "start_references"]


def start_references(
    group: SyncGroup, adjacency: np.ndarray, n_steps: int, params: BlenderParams
) -> tuple[np.ndarray, dict[str, float], np.ndarray | None]:
    """The best start's alteration fractions ``s`` (one per tick), the best mean r of each kind of start, and the
    best start's θ_ref if it is a constant frequency (else ``None``).

    Kinds: ``"none"`` (θ_ref = θ_L0), ``"mean"`` (the circular mean of the others), ``"constant"`` (the best
    constant frequency of the grid in the module docstring), all over the whole run.
    """
    omega = np.asarray(group.omega, dtype=float)
    scan_freq, scan_phase = (
        v.ravel() for v in np.meshgrid(np.linspace(omega.min() - 0.5, omega.max() + 0.5, 41), np.arange(4) * np.pi / 2)
    )
    # on the 0.05 rad/s lattice of constant_frequency_bound, where it is near the natural frequencies
    lattice = np.arange(-15.0, 15.0 + 1e-9, 0.05)  # the very values of constant_frequency_bound's grid
    dense = lattice[(lattice >= omega.min() - 1.0) & (lattice <= omega.max() + 1.0)]
    kind = np.r_[0, 1, np.full(len(scan_freq) + len(dense), 2)]
    rules = (kind, np.r_[0.0, 0.0, scan_phase, np.zeros(len(dense))], np.r_[0.0, 0.0, scan_freq, dense])
    state = initial_state(np.zeros(group.n), params.lam_max, params)
    sums, _ = rule_rollouts(group, adjacency, params, state, rules, n_steps, record=False)
    best = {name: float(sums[kind == k].max() / n_steps) for k, name in enumerate(("none", "mean", "constant"))}
    top = int(np.argmax(sums))
    _, s = rule_rollouts(group, adjacency, params, state, tuple(v[top : top + 1] for v in rules), n_steps, record=True)
    # the same expression as constant_frequency_bound's reference, so that re-simulations agree to the bit
    theta_ref = rules[1][top] + rules[2][top] * DT * np.arange(n_steps) if kind[top] == 2 else None
    return s[:, 0], best, theta_ref


def closed_loop_start(
    group: SyncGroup, adjacency: np.ndarray, params: BlenderParams, n_steps: int, motion: Any
) -> tuple[np.ndarray, np.ndarray]:
    """The alteration fractions and θ_ref of the motion computer ``motion`` (a fresh block) in closed loop."""
    d = Diagram()
    kuramoto = d.add("group", KuramotoGroup.for_group(group, adjacency=adjacency))
    blend = Blender(params=params)
    l2 = d.add("l2", L2Sync(motion, group.assisted, blend))
    d.connect(kuramoto.theta, l2.theta)
    d.connect(l2.theta_l2, kuramoto.theta_l2)
    trace = Simulator(d, probes=["l2.theta_l2", "l2.theta_l0", "l2.lam", "l2.theta_ref"]).run(n_steps=n_steps)
    alteration = np.mod(trace["l2.theta_l2"] - trace["l2.theta_l0"] + np.pi, 2 * np.pi) - np.pi
    return np.clip(alteration / trace["l2.lam"], -1.0, 1.0), trace["l2.theta_ref"]


def policy_starts(
    group: SyncGroup, adjacency: np.ndarray, params: BlenderParams, duration: float, pace: bool, guard: bool
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """The alteration fractions and θ_ref of the closed-loop policies that are starts too (identified models)."""
    motions = {}
    if pace:
        motions["pace"] = PacingMotion(group.n, group.assisted, adjacency=adjacency, blender=params)
    if guard:  # the guard rule, told the run's length
        motions["guard"] = GuardedPacingMotion.for_trial(
            group.n, group.assisted, adjacency=adjacency, blender=params, end=duration
        )
    n_steps = round(duration / DT) + 1
    return {name: closed_loop_start(group, adjacency, params, n_steps, motion) for name, motion in motions.items()}
