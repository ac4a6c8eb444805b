"""The noise gate: a planner's reference until the group's own prediction errors say it is noisy."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from cogblocks.blocks.specs import PHASE
from cogblocks.data.groups import GroupNoise, SyncGroup
from cogblocks.diagrams.sync import pop_sync
from cogblocks.sim import Block, Signal, Simulator
from cogblocks.sync.gated import NoiseGate, noise_gated

GROUP = SyncGroup("ring of 6", 6, 0.9, (2.0, 2.6, 3.1, 3.3, 4.0, 4.4), 2, 4.0)
SIGMA = 0.2
NOISY = dataclasses.replace(
    GROUP, noise=GroupNoise(sigma=(SIGMA,) * 6, drift_spread=(0.0,) * 6, drift_tau=10.0, seed=3)
)


class ConstantReference(Block):
    """A stand-in planner with the motion computers' ports: θ_ref = 1 rad, always."""

    def __init__(self, n: int) -> None:
        super().__init__()
        self.add_input("theta", PHASE.with_(shape=(n,)), feedthrough=False)
        self.add_input("lam", Signal(unit="rad"), default=math.pi, feedthrough=False)
        self.add_output("theta_ref", PHASE, initial=1.0)


def _run(group: SyncGroup, ticks: int = 401) -> tuple[dict, NoiseGate]:
    # the gate rebuilds θ_L2 with the deliverable's law (it does not yet take plan_through): its blender here
    motion = noise_gated(ConstantReference(group.n), group.n, group.assisted, adjacency=group.graph)
    sim = Simulator(
        pop_sync(group, motion=motion, blender="deliverable"),
        probes=["l2.theta_ref", "l2.motion.noisy", "l2.motion.fallback.theta_ref"],
    )
    trace = sim.run(n_steps=ticks)
    return trace, sim.compiled.blocks["l2.motion.gate"]


def test_a_deterministic_group_keeps_the_planner():
    trace, gate = _run(GROUP)
    assert gate.decided and gate.sigma_hat < 0.1 * gate.threshold
    np.testing.assert_array_equal(trace["l2.theta_ref"], 1.0)
    assert not trace["l2.motion.noisy"].any()


def test_a_noisy_group_is_recognised_and_falls_back_to_the_mean_after_the_decision():
    trace, gate = _run(NOISY)
    assert gate.sigma_hat == pytest.approx(SIGMA, rel=0.15)  # 200 ticks × 6 participants of residuals
    decided = 200  # decide_after = 2 s: the decision is taken in tick 199's update
    np.testing.assert_array_equal(trace["l2.theta_ref"][:decided], 1.0)
    np.testing.assert_array_equal(trace["l2.theta_ref"][decided:], trace["l2.motion.fallback.theta_ref"][decided:])
    assert not trace["l2.motion.noisy"][:decided].any() and trace["l2.motion.noisy"][decided:].all()


def test_the_gate_continues_bit_for_bit_from_a_snapshot():
    motion = noise_gated(ConstantReference(6), 6, 2)
    sim = Simulator(pop_sync(NOISY, motion=motion), probes=["l2.theta_ref"])
    sim.run(n_steps=150)
    state = sim.state_dict()
    first = sim.run(n_steps=200)
    sim.load_state_dict(state)
    np.testing.assert_array_equal(first["l2.theta_ref"], sim.run(n_steps=200)["l2.theta_ref"])


@pytest.mark.parametrize(
    ("options", "message"),
    [({"decide_after": 0.0}, "decide_after"), ({"threshold": -1.0}, "threshold"), ({"assisted": 6}, "assisted")],
)
def test_bad_gate_parameters_are_refused_by_name(options, message):
    kwargs = {"n": 6, "assisted": 2, **options}
    with pytest.raises(ValueError, match=message):
        NoiseGate(**kwargs)
