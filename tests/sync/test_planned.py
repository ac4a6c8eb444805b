"""The whole-trial plan (the planner with one decision): it does nothing while it identifies, then plays a plan its
model predicts right."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from cogblocks.data.groups import random_groups
from cogblocks.diagrams.sync import MOTIONS, pop_sync
from cogblocks.sim import Diagram, Simulator
from cogblocks.sync import RecedingPlanMotion
from cogblocks.sync.model import BlenderParams
from cogblocks.sync.planned import PlannedMotion, whole_trial_plan
from cogblocks.sync.whole_run import rule_rollouts

BLENDER = BlenderParams()
# validation group 4 (all-to-all, N = 3, unlocked), cut to 6 s: a plan of 5 s with one cheap sweep
GROUP = dataclasses.replace(random_groups(600, "validation", 0)[4], duration=6.0)
SWEEPS = ((2.0, 2.0, 0.25),)
N_TICKS = round(GROUP.duration / 0.01) + 1


def _block() -> RecedingPlanMotion:
    return whole_trial_plan(GROUP.n, GROUP.assisted, adjacency=GROUP.graph, end=GROUP.duration, sweeps=SWEEPS)


def _run(block: RecedingPlanMotion, l2: bool = True) -> dict:
    probes = {"l0": "l2.theta_l0", "l2": "l2.theta_l2", "ref": "l2.theta_ref"} if l2 else {}
    return Simulator(pop_sync(GROUP, l2=l2, motion=block, blender="deliverable"), probes=probes).run(n_steps=N_TICKS)


def _wrap(x: np.ndarray) -> np.ndarray:
    return np.mod(x + np.pi, 2 * np.pi) - np.pi


def test_the_plan_is_played_through_the_blender_and_its_model_predicts_the_group():
    block = _block()
    trace = _run(block)
    start = block.plan_start
    assert start == 101  # 100 increments identified at tick 100, planned from tick 101
    assert len(block.plans) == 1 and block.decision_period == np.inf  # one decision
    assert len(block.plan_a) == N_TICKS - start and np.all(np.isfinite(block.plan_a))
    alteration = _wrap(trace["l2"] - trace["l0"])
    np.testing.assert_array_equal(alteration[:start], 0.0)  # nothing altered while identifying
    # what reaches the group is the planned alteration: the planned λ is the blender's
    np.testing.assert_allclose(alteration[start:], block.plan_a, rtol=0, atol=1e-9)
    # the identified model predicts the real group's r (the blocks' simulation) over the whole plan
    np.testing.assert_allclose(block.plans[0][2], trace["r"][start:], rtol=0, atol=1e-4)
    assert block.decide_ms[0] > 0.0


def test_the_plan_raises_r_over_doing_nothing_and_over_the_mean_rule_from_the_same_state():
    block = _block()
    with_l2 = _run(block)["r"]
    without = _run(_block(), l2=False)["r"]
    np.testing.assert_allclose(with_l2[: block.plan_start], without[: block.plan_start], rtol=0, atol=1e-12)
    assert with_l2.mean() > without.mean() + 0.02
    # independent of the plan: the mean rule held from the planned state on the true group
    a = GROUP.adjacency()
    sim = Simulator(
        pop_sync(GROUP, motion=_block(), blender="deliverable"), probes={"l0": "l2.theta_l0", "th": "group.theta"}
    )
    theta = sim.run(n_steps=block.plan_start + 1)["th"][-1]
    lam = BLENDER.lam_max  # nothing altered before the plan: λ is still at its start
    rules = (np.array([0, 1]), np.zeros(2), np.zeros(2))
    sums, _ = rule_rollouts(GROUP, a, BLENDER, np.r_[theta, lam], rules, len(block.plan_a), record=False)
    assert with_l2[block.plan_start :].sum() > sums.max()


def test_motions_plan_is_told_the_group_and_the_trial():
    block = MOTIONS["plan"](GROUP)
    assert isinstance(block, RecedingPlanMotion) and block.decide_ticks is None and block.horizon_ticks is None
    np.testing.assert_array_equal(block.adjacency, GROUP.adjacency())
    assert block.end == GROUP.duration and block.assisted == GROUP.assisted


def test_a_plan_continues_bit_for_bit_from_a_snapshot():
    sim = Simulator(pop_sync(GROUP, motion=_block(), blender="deliverable"), probes={"ref": "l2.theta_ref"})
    sim.run(n_steps=250)
    snapshot = sim.state_dict()
    first = sim.run(n_steps=200)
    other = Simulator(pop_sync(GROUP, motion=_block(), blender="deliverable"), probes={"ref": "l2.theta_ref"})
    other.load_state_dict(snapshot)
    second = other.run(n_steps=200)
    np.testing.assert_array_equal(first["ref"], second["ref"])
    np.testing.assert_array_equal(first["r"], second["r"])


def test_a_bad_tick_identifies_nothing_and_theta_ref_holds():
    block = whole_trial_plan(3, 0, adjacency="all", end=1.0, min_ticks=5, sweeps=())
    d = Diagram()
    m = d.add("m", block)
    d.expose_input("theta", m.theta)
    d.expose_input("lam", m.lam)
    theta = np.outer(np.arange(8) * 0.01, [2.0, 3.0, 4.0]) % (2 * np.pi)
    theta[3] = np.nan
    lam = np.full(8, 1.0)
    ref = Simulator(d, probes={"ref": "m.theta_ref"}).run(n_steps=8, inputs={"theta": theta, "lam": lam})["ref"]
    assert ref[3] == ref[2] == theta[2, 0]  # held on the bad tick
    np.testing.assert_array_equal(ref[[0, 1, 2, 4, 5, 6, 7]], theta[[0, 1, 2, 4, 5, 6, 7], 0])  # nothing planned yet
    assert block.count == 5 and block.plan_a is None  # 0→1, 1→2, 4→5, 5→6, 6→7: none into or out of the bad tick


def test_the_block_plans_only_on_the_10_ms_tick():
    block = whole_trial_plan(GROUP.n, GROUP.assisted, adjacency=GROUP.graph, end=GROUP.duration, sweeps=())
    with pytest.raises(RuntimeError, match="0.01 s tick"):
        Simulator(pop_sync(GROUP, motion=block, blender="deliverable"), dt=0.02).run(n_steps=200)


@pytest.mark.parametrize(
    ("sweeps", "message"),
    [
        (((4.0, 4.0, 0.3),), "knot divide window"),
        (((4.0, -1.0, 0.25),), "tail >= 0"),
        (((0.0, 4.0, 0.25),), "window and knot"),
        (((4.0, 4.0),), "triples"),
        ((("a", 4.0, 0.25),), "triples"),
    ],
)
def test_bad_sweeps_are_refused_with_a_clear_message(sweeps, message):
    with pytest.raises(ValueError, match=message):
        whole_trial_plan(3, 0, end=10.0, sweeps=sweeps)


def test_a_whole_trial_plan_reaches_the_trials_end_and_is_made_inline():
    message = "decide_every=None plans the whole trial at once, in the tick it decides: it needs horizon=None"
    with pytest.raises(ValueError, match=message + r" and worker='inline', got horizon=5.0, worker='inline'"):
        RecedingPlanMotion(3, 0, end=10.0, decide_every=None, horizon=5.0)
    with pytest.raises(ValueError, match=message + r".* got horizon=None, worker='thread'"):
        RecedingPlanMotion(3, 0, end=10.0, decide_every=None, horizon=None, worker="thread")


def test_the_deprecated_class_warns_names_the_preset_and_plays_the_same_plan():
    with pytest.warns(
        DeprecationWarning, match=r"PlannedMotion is deprecated: whole_trial_plan\(n, assisted, end=\.\.\.\)"
    ):
        old = PlannedMotion(GROUP.n, GROUP.assisted, adjacency=GROUP.graph, end=GROUP.duration, sweeps=SWEEPS)
    new = _block()
    first, second = _run(old), _run(new)
    np.testing.assert_array_equal(first["ref"], second["ref"])
    np.testing.assert_array_equal(old.plan, new.plan_a)
    np.testing.assert_array_equal(old.predicted, new.plans[0][2])
    assert old.plan_ms == old.decide_ms[0]
