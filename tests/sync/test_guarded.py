"""The guarded pacing motion computer: its staged prediction, its bounded work per tick and its guard."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cogblocks.data.groups import TABLE2, SyncGroup, random_groups
from cogblocks.diagrams.sync import pop_sync
from cogblocks.sim import Diagram, Simulator
from cogblocks.sync.guarded import GuardedPacingMotion, phase_error
from cogblocks.sync.model import BlenderParams
from cogblocks.sync.pacing import MEAN, NONE, PACE, euler_step, predicted_order
from cogblocks.sync.staged import StagedPrediction

BLENDER = BlenderParams()


def _trial(group: SyncGroup) -> GuardedPacingMotion:
    """What the retired name ``guard`` builds: the guard told the trial's length."""
    return GuardedPacingMotion.for_trial(group.n, group.assisted, adjacency=group.graph, end=group.duration)


def _problem():
    rng = np.random.default_rng(3)
    n, assisted = 4, 1
    a = rng.uniform(0.0, 1.5, (n, n)) * (rng.random((n, n)) < 0.8)  # weighted, directed
    np.fill_diagonal(a, 0.0)
    return rng.uniform(0, 2 * np.pi, n), 1.2, (rng.uniform(1.0, 4.0, n), 0.7), a, assisted


def test_staged_prediction_is_the_lead_then_predicted_order_in_any_chunks():
    theta, lam, model, a, assisted = _problem()
    lead = (MEAN, math.pi, 0.0)
    cands = (np.array([NONE, MEAN, PACE, PACE]), np.array([0.0, 2.0, 2.5, 3.5]), np.array([0.0, 0.0, 1.0, -1.0]))
    # the lead by hand: 7 Euler steps of 1/7 s under the circular mean
    th, la = theta[None, :].copy(), np.array([lam])
    for s in range(7):
        th, la, _ = euler_step(th, la, model, a, assisted, BLENDER, tuple(np.array([v]) for v in lead), s / 7, 1 / 7)
    want = predicted_order(th[0], la[0], model, a, assisted, BLENDER, cands, step=0.05, steps=40)
    seen = []
    for budget in (1, 3, 47, 1000):
        job = StagedPrediction(
            theta,
            lam,
            model,
            a,
            assisted,
            BLENDER,
            lead,
            lead_time=1.0,
            lead_steps=7,
            fan_out=lambda t, la_: (seen.append((t.copy(), la_)), cands)[1],
            step=0.05,
            steps=40,
        )
        while not job.done:
            job.advance(budget)
            assert job.evaluations <= budget * 4
        np.testing.assert_allclose(job.lead_theta, th[0], rtol=0, atol=1e-12)
        np.testing.assert_allclose(job.scores, want, rtol=0, atol=1e-12)
    assert seen[0][1] == pytest.approx(la[0], abs=1e-12)  # the fan-out is given the lead's λ
    assert np.ptp(want) > 1e-3


@pytest.mark.parametrize(("end", "steps"), [(3.0, 30), (1.0, 400), (None, 400)])
def test_end_scores_a_prediction_only_up_to_the_runs_end(end, steps):
    """The first decision (started at tick 100, its lead ending at 1.5 s) is scored over the 1.5 s left before
    ``end`` = 3 s (30 steps of 50 ms); past ``end``, or without it, over the whole 20 s horizon."""
    group = TABLE2[1]
    block = GuardedPacingMotion(group.n, group.assisted, adjacency=group.graph, end=end)
    _closed_loop(group, block, 1.49, [])
    assert block.job.done and block.job.steps == steps
    with pytest.raises(ValueError, match="end must be"):
        GuardedPacingMotion(3, 0, end=-1.0)


def test_phase_error_ignores_a_common_offset():
    rng = np.random.default_rng(0)
    theta = rng.uniform(0, 2 * np.pi, 6)
    assert phase_error(theta + 2.0, theta) == pytest.approx(0.0, abs=1e-12)
    off = np.array([0.1, -0.1, 0.1, -0.1, 0.1, -0.1])
    assert phase_error(theta + 1.0 + off, theta) == pytest.approx(0.1, abs=1e-12)


def _closed_loop(group: SyncGroup, block: GuardedPacingMotion, seconds: float, record: list) -> dict:
    """Run ``block`` on ``group`` and record, after every update, the candidate-steps it did on that tick."""
    update = block.update

    def counted(k: int) -> None:
        update(k)
        job = block.job
        record.append(0 if job is None else job.evaluations)
        if job is not None:
            job.evaluations = 0  # a tick that does not advance it did no work

    block.update = counted
    probes = {"ref": "l2.theta_ref", "l0": "l2.theta_l0"}
    return Simulator(pop_sync(group, motion=block, blender="deliverable"), probes=probes).run(
        n_steps=round(seconds / 0.01) + 1
    )


def test_work_per_tick_is_bounded_and_a_decision_applies_one_period_after_it_starts():
    group = TABLE2[1]
    block = GuardedPacingMotion(
        group.n, group.assisted, adjacency=group.graph, decide_every=0.5, first_period=50, horizon=5.0
    )
    record: list[int] = []
    _closed_loop(group, block, 4.0, record)
    # 5 s of 50 ms steps and a 0.5 s lead of 10 steps, over 50 ticks: 3 Euler steps a tick, ≤ 38 candidates
    assert 3 * (1 + 3 + 2 * 16) <= max(record) <= 3 * (1 + 3 + 2 * 17)  # 38 candidates while pacing
    assert max(record) <= block.max_evaluations
    assert sum(r > 0 for r in record) >= 4 * 50  # the work is spread over the periods' ticks
    # the model is trusted after 100 increments (tick 100); decisions start at 100, 150, … and apply 50 ticks later
    assert len(block.errors) == len(block.choices) == (400 - 150) // 50 + 1
    assert max(block.errors) < block.tolerance  # a noiseless group of the identified kind: the model predicts well


def _start_ticks(block: GuardedPacingMotion) -> list[int]:
    """``block`` records the tick of every decision it starts in the returned list."""
    ticks: list[int] = []
    start = block._start

    def recorded(theta, lam, ref, model, k, dt) -> None:
        ticks.append(k)
        start(theta, lam, ref, model, k, dt)

    block._start = recorded
    return ticks


def test_the_first_decision_comes_after_half_a_period_then_decisions_come_every_period():
    """Until a check has passed, periods are ``first_period`` ticks: trusted at tick 100, the first decision is checked
    and applied at 150 (not 200), and later ones every 100 ticks; before 150 the participant is left unaltered."""
    group = TABLE2[1]
    # the class's own periods (for_trial, decides every 10 s): predictions stop at the group's 10 s
    block = GuardedPacingMotion(group.n, group.assisted, adjacency=group.graph, end=group.duration)
    assert block.first_period == 50 and block.decide_ticks == 100 and block.end == group.duration
    starts, record = _start_ticks(block), []
    trace = _closed_loop(group, block, 4.0, record)
    assert starts == [100, 150, 250, 350]
    assert len(block.errors) == 3 and max(block.errors) < block.tolerance
    assert block.choices[0] == PACE  # group 1 is paced from the first decision on
    ref, l0 = trace["ref"], trace["l0"]
    np.testing.assert_array_equal(ref[:150], l0[:150])  # start="none": θ_ref = θ_L0 until the first check
    assert np.abs(np.angle(np.exp(1j * (ref[150:] - l0[150:])))).max() > 0.1
    # the first period's decision is spread over 50 ticks: more steps a tick, within max_evaluations
    assert max(record) <= block.max_evaluations
    assert max(record[100:150]) > max(record[150:])


def test_the_default_policy_predicts_to_the_trials_end_at_the_groups_own_step():
    """The retired name ``guard`` builds ``for_trial``: trusted at tick 100, decisions start at 100 (a 3 s first
    period) and 400 (then every 10 s), and each fan-out scores its candidates at 10 ms steps up to the trial's end,
    not 20 s."""
    group = TABLE2[2]  # 300 s
    block = _trial(group)
    assert (block.end, block.step, block.decide_every, block.early, block.margin) == (
        group.duration,
        0.01,
        10.0,
        None,
        0,
    )
    assert block.first_period == 300 and _trial(TABLE2[1]).first_period == 100  # 30 000 steps over 300 ticks
    jobs = []
    start = block._start

    def recorded(theta, lam, ref, model, k, dt) -> None:
        start(theta, lam, ref, model, k, dt)
        jobs.append((k, block.job.lead_steps, block.job.steps, block.job.step))

    block._start = recorded
    trace = _closed_loop(group, block, 14.0, [])
    assert [job[0] for job in jobs] == [100, 400, 1400]
    for k, lead_steps, steps, step in jobs:
        lead_ticks = 300 if k == 100 else 1000  # the decision applies one period after it starts
        assert step == 0.01 and lead_steps == lead_ticks
        assert steps == round(group.duration / 0.01) - (k + lead_ticks)  # to the end, from the lead's end
    assert np.abs(np.angle(np.exp(1j * (trace["ref"] - trace["l0"])))).max() > 0.1  # it alters within the 14 s


def test_periods_stay_short_while_every_check_fails():
    """No check passes (frequencies that jump every 0.3 s): every decision period stays ``first_period`` ticks."""
    rng = np.random.default_rng(5)
    n, ticks = 4, 400
    rates = np.repeat(rng.uniform(-6.0, 6.0, (ticks // 30 + 1, n)), 30, axis=0)[:ticks]
    theta = np.mod(np.cumsum(rates * 0.01, axis=0), 2 * np.pi)
    block = GuardedPacingMotion(n, 0, first_period=30, horizon=2.0, min_excitation=0.0)
    starts = _start_ticks(block)
    _run_inputs(block, theta, np.full(ticks, 1.0))
    assert starts == list(range(100, ticks, 30))
    assert min(block.errors) > block.tolerance and set(block.choices) == {-1}


def test_a_committed_pace_is_kept_for_commit_periods():
    """With ``commit``, a pace once chosen is continued (same frequency, θ_ref = anchor + ω t without a jump) for
    ``commit`` periods; without it, the same group's pace is stopped half-way (validation group 429)."""
    group = random_groups(430, "validation", 0)[429]
    plain = GuardedPacingMotion(group.n, group.assisted, adjacency=group.graph, horizon=10.0, commit=0)
    _closed_loop(group, plain, group.duration, [])
    assert plain.choices[:4] == [PACE] * 4 and plain.choices[4] == NONE
    kept = GuardedPacingMotion(group.n, group.assisted, adjacency=group.graph, horizon=10.0, commit=10)
    values: list[float] = []
    finish = kept._finish

    def recorded(theta, ref, k, dt) -> bool:
        jumped = finish(theta, ref, k, dt)
        values.append(kept.value)
        return jumped

    kept._finish = recorded
    trace = _closed_loop(group, kept, group.duration, [])
    assert kept.choices == [PACE] * 10 and len(set(values)) == 1
    # from the first decision (tick 150) on, θ_ref advances by exactly ω dt a tick: one plan, never re-anchored
    step = np.angle(np.exp(1j * np.diff(trace["ref"][151:])))
    np.testing.assert_allclose(step, values[0] * 0.01, atol=1e-9)


def _run_inputs(block: GuardedPacingMotion, theta: np.ndarray, lam: np.ndarray) -> np.ndarray:
    d = Diagram()
    m = d.add("m", block)
    d.expose_input("theta", m.theta)
    d.expose_input("lam", m.lam)
    trace = Simulator(d, probes={"ref": "m.theta_ref"}).run(n_steps=len(theta), inputs={"theta": theta, "lam": lam})
    return trace["ref"]


def test_the_guard_falls_back_when_the_model_predicts_badly():
    """Phases that are no Kuramoto group (each frequency jumps every 0.3 s): every check fails, the block follows
    its fallback (the circular mean) from the first check on; the same block on smooth phases trusts its model."""
    rng = np.random.default_rng(5)
    n, ticks = 4, 600
    rates = np.repeat(rng.uniform(-6.0, 6.0, (ticks // 30 + 1, n)), 30, axis=0)[:ticks]
    theta = np.mod(np.cumsum(rates * 0.01, axis=0), 2 * np.pi)
    lam = np.full(ticks, 1.0)
    block = GuardedPacingMotion(
        n, 0, decide_every=0.5, first_period=50, horizon=2.0, fallback="mean", margin=0.0, min_excitation=0.0
    )
    ref = _run_inputs(block, theta, lam)
    assert len(block.errors) >= 8 and min(block.errors) > block.tolerance
    assert set(block.choices) == {-1}
    first = 100 + 50 + 1  # trusted at tick 100, checked at 150, applied from 151
    means = np.mod(np.arctan2(np.sin(theta[:, 1:]).sum(1), np.cos(theta[:, 1:]).sum(1)), 2 * np.pi)
    np.testing.assert_allclose(ref[first:], means[first:], atol=1e-12)
    np.testing.assert_array_equal(ref[:first], theta[:first, 0])  # before: start="none", θ_ref = θ_L0
    # constant frequencies (an uncoupled group, which the model fits but for its prior's ~1e-5): every check passes
    smooth = np.mod(np.arange(ticks)[:, None] * 0.01 * np.array([2.0, 3.0, 3.5, 4.0]) + np.arange(n), 2 * np.pi)
    calm = GuardedPacingMotion(n, 0, decide_every=0.5, horizon=2.0, fallback="mean", min_excitation=0.0)
    _run_inputs(calm, smooth, lam)
    assert max(calm.errors) < 1e-4 and -1 not in calm.choices


def test_bad_data_policy():
    """A bad tick identifies nothing; θ_ref holds (or keeps pacing); a decision in progress still advances."""
    n, ticks = 3, 160
    t = np.arange(ticks)[:, None] * 0.01
    theta = np.mod(np.array([2.0, 3.0, 4.0]) * t + np.array([0.0, 1.0, 2.5]), 2 * np.pi)
    lam = np.full(ticks, 1.0)
    theta[20, 1] = np.nan
    theta[70, 0] = 1e300
    lam[90] = np.inf
    block = GuardedPacingMotion(n, 0, start="mean", min_ticks=10, min_excitation=0.0, decide_every=0.5, horizon=1.0)
    ref = _run_inputs(block, theta, lam)
    assert np.isfinite(ref).all()
    assert ref[20] == ref[19] and ref[70] == ref[69]
    # 159 increments less those ending at or starting from a bad phase (19→20, 20→21, 69→70, 70→71) or λ (90, 91)
    assert block.count == 159 - 6
    # trusted at tick 10: decisions started at 10, 35 (one first_period of 25 ticks later: the first check passed), 85
    # and 135 (the one started at 135 ends at 185, after the run)
    assert len(block.errors) == 3


def test_guard_is_a_policy_of_the_held_out_runner_and_checks_its_parameters():
    group = SyncGroup("all", 4, 0.5, (2.0, 2.5, 3.0, 3.5), 1, 2.0, graph="all")
    block = _trial(group)
    assert isinstance(block, GuardedPacingMotion)
    np.testing.assert_array_equal(block.adjacency, group.adjacency())
    with pytest.raises(ValueError, match="fallback must be one of"):
        GuardedPacingMotion(3, 0, fallback="pace")
    with pytest.raises(ValueError, match="tolerance must be"):
        GuardedPacingMotion(3, 0, tolerance=-1.0)
    with pytest.raises(ValueError, match="first_period must be"):
        GuardedPacingMotion(3, 0, first_period=0)
    with pytest.raises(ValueError, match="commit must be"):
        GuardedPacingMotion(3, 0, commit=-1)


def test_staged_prediction_keeps_the_mean_r_up_to_its_checkpoint():
    """``early_scores`` is the fan-out's mean r over its first ``checkpoint`` steps: ``predicted_order`` over that
    many steps from the lead's end, whatever the chunks; past the horizon it is the whole fan-out's."""
    theta, lam, model, a, assisted = _problem()
    lead = (NONE, 0.0, 0.0)
    cands = (np.array([NONE, MEAN, PACE, PACE]), np.array([0.0, 2.0, 2.5, 3.5]), np.array([0.0, 0.0, 1.0, -1.0]))
    th, la = theta[None, :].copy(), np.array([lam])
    for s in range(5):
        th, la, _ = euler_step(th, la, model, a, assisted, BLENDER, tuple(np.array([v]) for v in lead), s / 10, 0.1)
    early = predicted_order(th[0], la[0], model, a, assisted, BLENDER, cands, step=0.05, steps=12)
    for checkpoint, budget, want in ((12, 1, early), (12, 13, early), (12, 1000, early), (99, 7, None)):
        job = StagedPrediction(
            theta, lam, model, a, assisted, BLENDER, lead, lead_time=0.5, lead_steps=5,
            fan_out=lambda t, la_: cands, step=0.05, steps=40, checkpoint=checkpoint,
        )  # fmt: skip
        while not job.done:
            job.advance(budget)
        np.testing.assert_allclose(job.early_scores, job.scores if want is None else want, rtol=0, atol=1e-12)
    assert np.ptp(early - job.scores) > 1e-3  # the checkpoint's means are not the horizon's
    plain = StagedPrediction(
        theta, lam, model, a, assisted, BLENDER, lead, lead_time=0.5, lead_steps=5,
        fan_out=lambda t, la_: cands, step=0.05, steps=40,
    )  # fmt: skip
    plain.advance(1000)
    with pytest.raises(RuntimeError, match="no checkpoint"):
        _ = plain.early_scores


def _chosen(block: GuardedPacingMotion) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """``block`` records, at every choice, the index chosen, the early and the whole-horizon scores."""
    record: list[tuple[int, np.ndarray, np.ndarray]] = []
    committed = block._committed

    def recorded(kinds: np.ndarray, scores: np.ndarray) -> int:
        best = committed(kinds, scores)
        record.append((best, block.job.early_scores.copy(), block.job.scores.copy()))
        return best

    block._committed = recorded
    return record


def test_early_alters_only_where_the_gain_shows_within_early_seconds():
    """Seed 3's test group 100 (development data since its report): at 11.5 s, without ``early``, the block starts a
    pace predicted to gain 0.048 in mean r over 20 s and nothing over the first 10 s; with ``early=10`` (the default)
    no alteration is chosen whose predicted mean r over its first 10 s is below doing nothing's, and that pace is not
    started."""
    group = random_groups(101, "test", 3)[100]
    plain = GuardedPacingMotion(group.n, group.assisted, adjacency=group.graph, end=group.duration, early=None)
    _closed_loop(group, plain, 12.6, [])
    assert plain.choices[:10] == [NONE] * 10 and plain.choices[10] == PACE
    early = GuardedPacingMotion(group.n, group.assisted, adjacency=group.graph, end=group.duration)
    assert early.early == 10.0
    record = _chosen(early)
    _closed_loop(group, early, 12.6, [])
    assert early.job.checkpoint == 200  # 10 s of 50 ms steps
    assert early.choices[10] != PACE
    vetoed = 0
    for best, early_scores, scores in record:
        assert best == 0 or early_scores[best] >= early_scores[0]
        vetoed += int(np.argmax(scores) != 0 and early_scores[np.argmax(scores)] < early_scores[0])
    assert vetoed >= 1  # the option did act on this run
    for bad in (0.0, -1.0, math.nan):
        with pytest.raises(ValueError, match="early must be"):
            GuardedPacingMotion(3, 0, early=bad)


def test_a_decision_with_a_checkpoint_continues_bit_for_bit_from_a_snapshot():
    """Saved while a decision's fan-out is past its checkpoint (tick 123 of the one started at 100, 5 s = 100 steps
    in), the diagram continues to the bit in a new diagram built alike."""
    group = TABLE2[2]

    def build() -> GuardedPacingMotion:
        return GuardedPacingMotion(group.n, group.assisted, adjacency=group.graph, end=group.duration, early=5.0)

    sim = Simulator(pop_sync(group, motion=build(), blender="deliverable"), probes={"ref": "l2.theta_ref"})
    sim.run(n_steps=123)
    job = sim.compiled.blocks["l2.motion"].job
    assert job.done_steps - job.lead_steps > job.checkpoint and not job.done and len(job.early)
    snapshot = sim.state_dict()
    first = sim.run(n_steps=300)
    other = Simulator(pop_sync(group, motion=build(), blender="deliverable"), probes={"ref": "l2.theta_ref"})
    other.load_state_dict(snapshot)
    second = other.run(n_steps=300)
    np.testing.assert_array_equal(first["r"], second["r"])
    np.testing.assert_array_equal(first["ref"], second["ref"])
