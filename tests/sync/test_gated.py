"""The gate: a motion computer's reference until the group's own prediction errors say it is noisy."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from cogblocks.blocks import Playback
from cogblocks.blocks.angles import wrap_pi
from cogblocks.blocks.specs import PHASE
from cogblocks.data.groups import GroupNoise, SyncGroup
from cogblocks.diagrams.sync import MOTIONS, pop_sync
from cogblocks.diagrams.sync_motions import _replan_motion
from cogblocks.sim import Block, Signal, Simulator
from cogblocks.sync import Blender, GatedMotion, MeanPhaseMotion
from cogblocks.sync.blending import CONTINUOUS, DELIVERABLE, BlenderParams
from cogblocks.sync.gated import NoiseGate

GROUP = SyncGroup("ring of 6", 6, 0.9, (2.0, 2.6, 3.1, 3.3, 4.0, 4.4), 2, 4.0)
SIGMA = 0.2
NOISY = dataclasses.replace(
    GROUP, noise=GroupNoise(sigma=(SIGMA,) * 6, drift_spread=(0.0,) * 6, drift_tau=10.0, seed=3)
)
PROBES = ["l2.theta_ref", "l2.theta_l0", "l2.motion.noisy", "l2.motion.fallback.theta_ref"]


class ConstantReference(Block):
    """A stand-in motion computer: θ_ref = 1 rad, always; it records the blender it is handed."""

    def __init__(self, n: int, known: bool = True) -> None:
        super().__init__()
        if known:  # the group's size and the assisted participant, as motion computers say them
            self.n, self.assisted = n, GROUP.assisted
        self.handed: BlenderParams | None = None
        self.add_input("theta", PHASE.with_(shape=(n,)), feedthrough=False)
        self.add_input("lam", Signal(unit="rad"), default=math.pi, feedthrough=False)
        self.add_output("theta_ref", PHASE, initial=1.0)

    def plan_through(self, blender: BlenderParams) -> None:
        self.handed = blender


def _run(group: SyncGroup, blender: str = "continuous", ticks: int = 401, **options) -> tuple[dict, GatedMotion]:
    motion = GatedMotion(ConstantReference(group.n), adjacency=group.graph, **options)
    probes = PROBES if "fallback" in motion else PROBES[:-1]
    trace = Simulator(pop_sync(group, motion=motion, blender=blender), probes=probes).run(n_steps=ticks)
    return trace, motion


@pytest.mark.parametrize("blender", ["continuous", "deliverable"])
def test_a_deterministic_group_keeps_the_model_behind_either_blender(blender):
    # a constant reference crosses ±π every cycle of θ_L0: the two laws differ there, the rebuilt phases do not
    trace, motion = _run(GROUP, blender)
    assert motion.world == "model" and motion.sigma_hat < 1e-4
    np.testing.assert_array_equal(trace["l2.theta_ref"], 1.0)
    assert not trace["l2.motion.noisy"].any()


def test_the_gate_rebuilds_the_phases_through_the_blender_it_is_handed():
    # the same gate told the wrong law (the deliverable's, behind the continuous blender) sees prediction errors
    _, right = _run(GROUP)
    motion = GatedMotion(ConstantReference(GROUP.n), adjacency=GROUP.graph)
    diagram = pop_sync(GROUP, motion=motion)
    assert motion["model"].handed == CONTINUOUS and motion["gate"].blender == CONTINUOUS
    motion["gate"].plan_through(DELIVERABLE)
    Simulator(diagram).run(n_steps=401)
    assert motion.sigma_hat > 1000 * right.sigma_hat


def test_a_blender_swapped_in_reaches_the_model_and_the_gate():
    motion = GatedMotion(ConstantReference(GROUP.n), adjacency=GROUP.graph)
    diagram = pop_sync(GROUP, motion=motion)
    diagram.replace("l2.blender", Blender())
    assert motion["model"].handed == DELIVERABLE and motion["gate"].blender == DELIVERABLE
    motion.replace("model", ConstantReference(GROUP.n))  # a model swapped inside the wrapper is told too
    assert motion["model"].handed == DELIVERABLE


def test_a_noisy_group_is_recognised_and_falls_back_to_the_mean_after_the_decision():
    trace, motion = _run(NOISY, decide_after=2.0)
    assert motion.sigma_hat == pytest.approx(SIGMA, rel=0.15)  # 200 ticks × 6 participants of residuals
    decided = 200  # decide_after = 2 s: the decision is taken in tick 199's update
    np.testing.assert_array_equal(trace["l2.theta_ref"][:decided], 1.0)
    np.testing.assert_array_equal(trace["l2.theta_ref"][decided:], trace["l2.motion.fallback.theta_ref"][decided:])
    assert not trace["l2.motion.noisy"][:decided].any() and trace["l2.motion.noisy"][decided:].all()
    assert motion.world == "noisy"


def test_the_fallback_can_be_doing_nothing():
    trace, motion = _run(NOISY, fallback="nothing", decide_after=2.0)
    assert "fallback" not in motion and motion.world == "noisy"
    np.testing.assert_array_equal(trace["l2.theta_ref"][200:], trace["l2.theta_l0"][200:])


def test_the_world_is_undecided_before_the_first_decision_and_checked_again_later():
    # one participant's frequency steps by 3 rad/s at 2.5 s, after the first decision: the fit of constant
    # frequencies leaves errors from then on, which a later check (every check_every = 1 s) sees
    omega = np.tile(GROUP.omega, (800, 1))
    omega[250:, 0] += 3.0
    motion = GatedMotion(ConstantReference(GROUP.n), adjacency=GROUP.graph, decide_after=2.0)
    diagram = pop_sync(GROUP, motion=motion)
    diagram.add("omega", Playback(omega, unit="rad/s"))
    diagram.connect("omega.y", "group.omega")
    sim = Simulator(diagram, probes=["l2.motion.noisy"])
    sim.run(n_steps=150)
    assert motion.world == "undecided" and math.isnan(motion.sigma_hat)
    sim.run(n_steps=100)
    assert motion.world == "model"
    trace = sim.run(n_steps=550)
    assert motion.world == "noisy"
    switched = 250 + int(np.argmax(trace["l2.motion.noisy"]))
    assert switched >= 300 and switched % 100 == 0  # a check, after the step


def test_the_gate_continues_bit_for_bit_from_a_snapshot():
    motion = GatedMotion(ConstantReference(6), adjacency="ring")
    sim = Simulator(pop_sync(NOISY, motion=motion), probes=["l2.theta_ref"])
    sim.run(n_steps=150)
    state = sim.state_dict()
    first = sim.run(n_steps=200)
    sim.load_state_dict(state)
    np.testing.assert_array_equal(first["l2.theta_ref"], sim.run(n_steps=200)["l2.theta_ref"])


def test_gated_is_registered_around_replan_and_reports_its_world():
    motion = MOTIONS["gated"](GROUP)
    assert isinstance(motion, GatedMotion) and type(motion["model"]) is type(_replan_motion(GROUP))
    assert motion.decision_period == motion["model"].decision_period
    np.testing.assert_array_equal(motion["gate"].rls.adjacency, motion["model"].adjacency)


def test_a_model_without_its_graph_needs_one():
    with pytest.raises(ValueError, match="GatedMotion: adjacency must be given"):
        GatedMotion(MeanPhaseMotion(4, 1))
    with pytest.raises(ValueError, match="GatedMotion: give n and assisted"):
        GatedMotion(ConstantReference(4, known=False), adjacency="ring")
    with pytest.raises(ValueError, match="GatedMotion: model must be a Block with inputs"):
        GatedMotion(Blender(), adjacency="ring")


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"decide_after": 0.0}, "decide_after"),
        ({"check_every": -1.0}, "check_every"),
        ({"threshold": -1.0}, "threshold"),
        ({"assisted": 6}, "assisted"),
        ({"fallback": "median"}, "fallback must be one of"),
        ({"blender": "continuous"}, "blender must be a BlenderParams"),
    ],
)
def test_bad_gate_parameters_are_refused_by_name(options, message):
    kwargs = {"n": 6, "assisted": 2, **options}
    with pytest.raises(ValueError, match=message):
        NoiseGate(**kwargs)


def test_a_gated_planner_stops_deciding_once_the_fallback_plays_for_good():
    group = dataclasses.replace(NOISY, duration=4.0)
    motion = MOTIONS["gated"](group)
    trace = Simulator(pop_sync(group, motion=motion), probes=["l2.motion.idle.theta_model"]).run(n_steps=401)
    assert motion.world == "noisy"
    switch = round(motion["gate"].decide_after / 0.01)  # the first tick the fallback plays
    seen = trace["l2.motion.idle.theta_model"]
    assert np.isfinite(seen[: switch + 1]).all() and np.isnan(seen[switch + 1 :]).all()  # one tick after the switch
    planner = motion["model"]
    assert planner.plans and max(start for start, _, _ in planner.plans) <= switch + 100  # nothing decided after it


def test_on_a_deterministic_group_gated_is_replan_tick_for_tick():
    group = dataclasses.replace(GROUP, duration=3.0)
    traces = {
        name: Simulator(pop_sync(group, motion=MOTIONS[name](group)), probes=["l2.theta_l2", "l2.theta_l0"]).run(
            n_steps=301
        )
        for name in ("gated", "replan")
    }
    altered = np.abs(wrap_pi(traces["replan"]["l2.theta_l2"] - traces["replan"]["l2.theta_l0"]))
    assert altered.max() > 0.1  # the planner does alter: the comparison is not between two idle runs
    np.testing.assert_array_equal(traces["gated"]["l2.theta_l2"], traces["replan"]["l2.theta_l2"])
    np.testing.assert_array_equal(traces["gated"]["r"], traces["replan"]["r"])
