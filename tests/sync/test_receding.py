"""The receding-plan motion computer: it identifies, then re-plans every period from what it observes, inline or on a
thread that a live run at 100 Hz does not wait for."""

from __future__ import annotations

import dataclasses
import threading

import numpy as np
import pytest

from cogblocks.data.groups import random_groups
from cogblocks.diagrams.sync import MOTIONS, pop_sync
from cogblocks.sim import Diagram, Simulator
from cogblocks.sync import RecedingPlanMotion
from cogblocks.sync.blending import CONTINUOUS
from cogblocks.sync.model import BlenderParams
from cogblocks.sync.whole_run import rule_rollouts

BLENDER = BlenderParams()
# validation group 4 (all-to-all, N = 3, unlocked), cut to 6 s: plans of 3 s every second, one cheap sweep
GROUP = dataclasses.replace(random_groups(600, "validation", 0)[4], duration=6.0)
OPTIONS = {"decide_every": 1.0, "horizon": 3.0, "sweeps": ((2.0, 2.0, 0.25),), "min_ticks": 100}
N_TICKS = round(GROUP.duration / 0.01) + 1
PROBES = {"l0": "l2.theta_l0", "l2": "l2.theta_l2", "ref": "l2.theta_ref"}


def _block(**options) -> RecedingPlanMotion:
    return RecedingPlanMotion(
        GROUP.n, GROUP.assisted, adjacency=GROUP.graph, end=GROUP.duration, **{**OPTIONS, **options}
    )


def _run(block: RecedingPlanMotion, l2: bool = True, n_steps: int = N_TICKS) -> dict:
    return Simulator(pop_sync(GROUP, l2=l2, motion=block, blender="deliverable"), probes=PROBES if l2 else {}).run(
        n_steps=n_steps
    )


def _wrap(x: np.ndarray) -> np.ndarray:
    return np.mod(x + np.pi, 2 * np.pi) - np.pi


def _planned(block: RecedingPlanMotion, n_ticks: int) -> tuple[np.ndarray, np.ndarray]:
    """Tick by tick, the alteration of the plan in force and its predicted r (NaN where no plan is)."""
    alteration, r = np.zeros(n_ticks), np.full(n_ticks, np.nan)
    for start, a, predicted in block.plans:
        alteration[start : start + len(a)], r[start : start + len(a)] = a, predicted
    return alteration, r


def test_every_period_a_new_plan_is_played_and_its_model_predicts_the_group():
    block = _block()
    trace = _run(block)
    starts = [start for start, _, _ in block.plans]
    # identified at tick 100, so decisions at 100, 200, …; each takes effect one period after it starts
    assert starts == [200, 300, 400, 500, 600]
    assert len(block.decide_ms) == 5 and min(block.decide_ms) > 0.0 and block.late == 0
    assert [len(a) for _, a, _ in block.plans] == [300, 300, 201, 101, 1]  # 3 s, cut at the trial's end
    alteration, predicted = _planned(block, N_TICKS)
    seen = _wrap(trace["l2"] - trace["l0"])
    np.testing.assert_array_equal(seen[:200], 0.0)  # nothing altered while identifying and deciding first
    np.testing.assert_allclose(seen, alteration, rtol=0, atol=1e-9)  # the plan in force reaches the group
    # the identified model, re-identified while altering, predicts the group's r over every period
    np.testing.assert_allclose(predicted[200:], trace["r"][200:], rtol=0, atol=1e-4)


def test_the_plans_raise_r_over_doing_nothing_and_over_the_mean_rule_from_the_same_state():
    block = _block()
    with_l2 = _run(block)["r"]
    without = _run(_block(), l2=False)["r"]
    np.testing.assert_allclose(with_l2[:200], without[:200], rtol=0, atol=1e-12)
    assert with_l2.mean() > without.mean() + 0.02
    # independent of the plans: doing nothing and the mean rule from tick 200's state on the true group
    theta = Simulator(pop_sync(GROUP, motion=_block(), blender="deliverable"), probes={"th": "group.theta"}).run(
        n_steps=201
    )["th"][-1]
    rules = (np.array([0, 1]), np.zeros(2), np.zeros(2))
    sums, _ = rule_rollouts(
        GROUP, GROUP.adjacency(), BLENDER, np.r_[theta, BLENDER.lam_max], rules, N_TICKS - 200, record=False
    )
    assert with_l2[200:].sum() > sums.max()


def test_motions_replan_is_told_the_group_and_the_trial():
    block = MOTIONS["replan"](GROUP)
    assert isinstance(block, RecedingPlanMotion) and block.worker == "inline"
    np.testing.assert_array_equal(block.adjacency, GROUP.adjacency())
    assert block.end == GROUP.duration and block.assisted == GROUP.assisted


def test_plans_continue_bit_for_bit_from_a_snapshot_taken_between_a_decision_and_its_plan(tmp_path):
    sim = Simulator(pop_sync(GROUP, motion=_block(), blender="deliverable"), probes={"ref": "l2.theta_ref"})
    sim.run(n_steps=250)  # the decision of tick 200 is pending until tick 300
    snapshot = sim.state_dict()
    sim.save_state(tmp_path / "snap.npz")  # and to a file, without pickle
    first = sim.run(n_steps=200)
    for load in (lambda other: other.load_state_dict(snapshot), lambda other: other.load_state(tmp_path / "snap.npz")):
        other = Simulator(pop_sync(GROUP, motion=_block(), blender="deliverable"), probes={"ref": "l2.theta_ref"})
        load(other)
        assert other.compiled.blocks["l2.motion"].pending_start == 300
        second = other.run(n_steps=200)
        np.testing.assert_array_equal(first["ref"], second["ref"])
        np.testing.assert_array_equal(first["r"], second["r"])


@pytest.mark.realtime
def test_on_a_thread_in_real_time_the_plans_are_those_of_its_timeline_replayed(replayed_planner):
    from cogblocks.live import run_realtime

    threaded = _block(worker="thread")
    d = pop_sync(GROUP, motion=threaded, blender="deliverable")
    d.expose_output("r", "order.r")
    report = run_realtime(d.compile(0.01), N_TICKS / 100.0, record=True)
    threaded.close()
    assert threaded.timeline and len(threaded.decide_ms) >= len(threaded.plans)
    replayed = replayed_planner(
        threaded.timeline, GROUP.n, GROUP.assisted, adjacency=GROUP.graph, end=GROUP.duration, **OPTIONS
    )
    expected = _run(replayed)["r"]
    assert [start for start, _, _ in threaded.plans] == [start for start, _, _ in replayed.plans]
    assert replayed.late == threaded.late and replayed.timeline == threaded.timeline
    np.testing.assert_allclose(report.trace["r"], expected, rtol=0, atol=1e-12)


def test_a_timeline_without_late_decisions_replays_as_the_inline_run(replayed_planner):
    inline = _block()
    expected = _run(inline)["r"]
    replayed = replayed_planner(
        inline.timeline, GROUP.n, GROUP.assisted, adjacency=GROUP.graph, end=GROUP.duration, **OPTIONS
    )
    np.testing.assert_array_equal(_run(replayed)["r"], expected)
    assert replayed.late == 0 and [p[0] for p in replayed.plans] == [p[0] for p in inline.plans]


class _HeldDecision(RecedingPlanMotion):
    """Decides only once the test lets it: a decision that cannot finish within its period."""

    def __init__(self, release: threading.Event, **options) -> None:
        super().__init__(GROUP.n, GROUP.assisted, adjacency=GROUP.graph, end=GROUP.duration, **options)
        self.release = release

    def _decide(self, *task):
        self.release.wait(timeout=30.0)
        return super()._decide(*task)


def test_a_late_decision_is_counted_and_dropped_while_the_plan_in_force_goes_on(replayed_planner):
    release = threading.Event()
    block = _HeldDecision(release, worker="thread", **OPTIONS)
    sim = Simulator(pop_sync(GROUP, motion=block, blender="deliverable"), probes=PROBES)
    first = sim.run(n_steps=350)
    assert block.late == 1 and block.plans == []  # the decision of tick 100 was due at tick 200
    np.testing.assert_array_equal(_wrap(first["l2"] - first["l0"]), 0.0)  # no plan: nothing altered
    release.set()
    block._future.result(timeout=30.0)
    middle = sim.run(n_steps=1)
    # its plan's start, tick 200, has passed: dropped
    assert block.pending_start == -1 and block.pending_a is None and block.plans == []
    assert block._future is not None and block.next_decision == 450  # decided again at tick 350, the worker free
    block._future.result(timeout=30.0)
    second = sim.run(n_steps=N_TICKS - 351)
    start, a, _ = block.plans[0]
    assert start == 450  # (later decisions may be late: this simulation runs faster than real time)
    np.testing.assert_allclose(_wrap(second["l2"] - second["l0"])[99:199], a[:100], rtol=0, atol=1e-9)
    block.close()
    assert block._executor is None and block._future is None
    # its timeline replayed offline: the same late decisions dropped, the same plans, the same avatar
    replayed = replayed_planner(
        block.timeline, GROUP.n, GROUP.assisted, adjacency=GROUP.graph, end=GROUP.duration, **OPTIONS
    )
    again = _run(replayed)
    live = np.concatenate([part["l2"] for part in (first, middle, second)])
    np.testing.assert_allclose(again["l2"], live, rtol=0, atol=1e-12)
    assert replayed.late == block.late >= 1 and [p[0] for p in replayed.plans] == [p[0] for p in block.plans]


def test_a_bad_tick_identifies_nothing_and_theta_ref_holds():
    block = RecedingPlanMotion(3, 0, adjacency="all", end=1.0, min_ticks=5, decide_every=0.5, sweeps=())
    d = Diagram()
    m = d.add("m", block)
    d.expose_input("theta", m.theta)
    d.expose_input("lam", m.lam)
    theta = np.outer(np.arange(8) * 0.01, [2.0, 3.0, 4.0]) % (2 * np.pi)
    theta[3] = np.nan
    lam = np.full(8, 1.0)
    ref = Simulator(d, probes={"ref": "m.theta_ref"}).run(n_steps=8, inputs={"theta": theta, "lam": lam})["ref"]
    assert ref[3] == ref[2] == theta[2, 0]  # held on the bad tick
    np.testing.assert_array_equal(ref[[0, 1, 2, 4, 5, 6, 7]], theta[[0, 1, 2, 4, 5, 6, 7], 0])  # no plan yet
    assert block.count == 5  # 0→1, 1→2, 4→5, 5→6, 6→7: none into or out of the bad tick


def test_the_block_plans_only_on_the_10_ms_tick():
    block = _block(sweeps=())
    with pytest.raises(RuntimeError, match="0.01 s tick"):
        Simulator(pop_sync(GROUP, motion=block, blender="deliverable"), dt=0.02).run(n_steps=200)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"decide_every": 0.015}, "multiple of 0.01 s"),
        ({"horizon": 0.5}, "at least decide_every"),
        ({"sweeps": ((4.0, 4.0, 0.3),)}, "knot divide window"),
        ({"worker": "process"}, "worker"),
    ],
)
def test_bad_options_are_refused_with_a_clear_message(options, message):
    with pytest.raises(ValueError, match=message):
        _block(**options)


def test_a_plan_that_does_not_beat_doing_nothing_by_the_margin_is_not_played():
    without = _run(_block(), l2=False)["r"]
    altered = _block()  # the default margin, 1e-4: this unlocked group's plans gain far more
    _run(altered)
    assert any(np.any(a != 0.0) for _, a, _ in altered.plans)
    idle = _block(margin=1.0)  # more than r can gain: every decision is to do nothing
    trace = _run(idle)
    assert len(idle.plans) == 5 and all(np.all(a == 0.0) for _, a, _ in idle.plans)
    np.testing.assert_array_equal(_wrap(trace["l2"] - trace["l0"]), 0.0)
    np.testing.assert_allclose(trace["r"], without, rtol=0, atol=1e-12)


def test_past_the_plan_in_force_a_decision_expects_the_best_rule_not_nothing():
    # plans as long as the period and no sweeps: a later decision's warm start is all extension, played as it is
    probes = {"l0": "l2.theta_l0", "l2": "l2.theta_l2", "theta": "group.theta", "lam": "l2.lam"}
    runs = {}
    for extend in ("rule", "nothing"):
        block = _block(horizon=1.0, sweeps=(), extend=extend)
        runs[extend] = (
            block,
            Simulator(pop_sync(GROUP, motion=block, blender="deliverable"), probes=probes).run(n_steps=N_TICKS),
        )
    block, trace = runs["rule"]
    others = np.delete(trace["theta"], GROUP.assisted, axis=1)
    mean = np.angle(np.exp(1j * others).sum(axis=1))
    follow_mean = np.clip(_wrap(mean - trace["l0"]), -trace["lam"], trace["lam"])  # the mean rule, on the group
    altered = _wrap(trace["l2"] - trace["l0"])
    assert [start for start, _, _ in block.plans] == [200, 300, 400, 500, 600]
    for start, a, _ in block.plans[1:]:  # on this unlocked group the mean is the best rule
        assert np.abs(a).max() > 0.3
        np.testing.assert_allclose(altered[start : start + len(a)], follow_mean[start : start + len(a)], atol=1e-3)
    idle, idle_trace = runs["nothing"]
    assert all(np.all(a == 0.0) for _, a, _ in idle.plans[1:])  # nothing expected, nothing found better
    assert trace["r"].mean() > idle_trace["r"].mean() + 0.03


def test_with_no_horizon_every_plan_reaches_the_trials_end():
    block = _block(horizon=None, compare=None)
    _run(block)
    assert [(start, len(a)) for start, a, _ in block.plans] == [
        (200, 401),
        (300, 301),
        (400, 201),
        (500, 101),
        (600, 1),
    ]
    with pytest.raises(ValueError, match="horizon=None plans to the trial's end, which needs end"):
        RecedingPlanMotion(3, 0, end=None, horizon=None)


def test_through_the_continuous_blender_the_plan_is_what_the_avatar_does_and_never_jumps():
    block = _block()
    trace = Simulator(pop_sync(GROUP, motion=block, blender="continuous"), probes=PROBES).run(n_steps=N_TICKS)
    assert block.blender == CONTINUOUS and [start for start, _, _ in block.plans][0] == 200
    alteration, predicted = _planned(block, N_TICKS)
    seen = _wrap(trace["l2"] - trace["l0"])
    # the plans are made through the slew limit: the blender passes them unchanged, and the model predicts r
    np.testing.assert_allclose(seen, alteration, rtol=0, atol=1e-9)
    np.testing.assert_allclose(predicted[200:], trace["r"][200:], rtol=0, atol=1e-4)
    assert np.abs(np.diff(seen)).max() <= CONTINUOUS.slew * 0.01 + 1e-9
