"""The optimised blender's spread solve following the emitted past (``track_past``, real-time iteration)."""

import types

import numpy as np
import pytest
import torch

import cogblocks.amplification.decision as decision
import cogblocks.amplification.optimal as optimal
from cogblocks.amplification import OptimalBlender
from cogblocks.amplification.linearised import LinearisedRun
from cogblocks.amplification.plan import plan_problem, with_past
from cogblocks.diagrams.amplification import replay_movement
from studies.amplification_gap import planned_vs_emitted, summarise
from studies.amplification_inner import inner_setup
from tests.amplification.optimal_helpers import options, plain_blender

torch.set_num_threads(1)

#: The entries of a problem that are arrays or lists (``kinematics`` is compared through its base).
ENTRIES = ("x0", "A", "H", "q", "C", "g0", "d", "rhs", "knots", "phi", "phi0", "u_prev")


def replay(setup, blender, human):
    return replay_movement(setup, human, blender)


def assert_same_problem(got, expected, atol=1e-12):
    assert set(got) == set(expected)
    for key in ENTRIES:
        np.testing.assert_allclose(np.asarray(got[key], float), np.asarray(expected[key], float), rtol=0, atol=atol)
    if "kinematics" in expected:
        np.testing.assert_allclose(got["kinematics"].base, expected["kinematics"].base, rtol=0, atol=atol)


class CommitRecorder(OptimalBlender):
    """Keeps, at every commit, the committed problem and the problem built from scratch with the records then."""

    def reset(self) -> None:
        super().reset()
        self.pairs = []

    def _finish(self, t, new):
        job = self._job
        if job["problem"] is not None and t >= job["t0"]:
            reference = self.library.velocity[job["reference"]]
            rhs = [self._sign, self._z_target, self.end_speed, self._delta]
            scratch = plan_problem(
                job["t0"], job["length"], job["predicted"], self.altered, self.human, reference, self.knot_spacing,
                self.dt, rhs, self.subspace, self.realism, self.kinematics,
            )  # fmt: skip
            self.pairs.append((job["problem"], scratch))
        return super()._finish(t, new)


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("kinematics", [False, True])
def test_with_past_is_the_problem_of_that_past(setup, seed, kinematics):
    rng = np.random.default_rng(seed)
    n, t, length = setup.library.max_len, 30, 70
    predicted = np.zeros((n, 3))
    predicted[20:] = rng.normal(scale=80.0, size=(n - 20, 3))
    reference = rng.normal(scale=80.0, size=(n, 3))
    rhs = [1.0 if setup.e_des else -1.0, 6.9, 5.0, 15.0]
    pasts = [(rng.normal(scale=60.0, size=(n, 3)), rng.normal(scale=60.0, size=(n, 3))) for _ in range(2)]
    args = (predicted, reference, 10, 0.01, rhs, setup.subspace, 3000.0, kinematics)
    first = plan_problem(t, length, predicted, *pasts[0], *args[1:])
    expected = plan_problem(t, length, predicted, *pasts[1], *args[1:])
    got = with_past(first, t, length, predicted, *pasts[1], reference, 0.01, rhs, setup.subspace, 3000.0)
    assert_same_problem(got, expected, atol=1e-12)
    assert got["A"] is first["A"] and got["H"] is first["H"]  # the knots' part is shared, not rebuilt
    assert not np.allclose(got["x0"], first["x0"])  # and the fixed part did change


def test_committed_problem_is_the_true_past(setup, networks):
    blender = CommitRecorder(
        setup.movements, networks, setup.table, e_des=setup.e_des, subspace=setup.subspace,
        **options(track_past=True),
    )  # fmt: skip
    replay(setup, blender, int(setup.humans[0]))
    assert len(blender.pairs) >= 3
    for got, scratch in blender.pairs:
        assert_same_problem(got, scratch, atol=1e-12)
    # the kept plan was judged on that problem: the check at the commit agrees with the solver's acceptance
    committed = [r for r in blender.results if r.status in ("converged", "accepted")]
    clipped = [r.eps > 0.9 if setup.e_des else r.eps < 0.1 for r in committed]
    assert np.mean(clipped) >= 0.9


def test_off_never_touches_the_problem(setup, networks, monkeypatch):
    def forbidden(*args, **kwargs):
        raise AssertionError("the option is off")

    monkeypatch.setattr(decision, "follow_past", forbidden)
    monkeypatch.setattr(LinearisedRun, "update", forbidden)
    blender = CommitRecorder(
        setup.movements, networks, setup.table, e_des=setup.e_des, subspace=setup.subspace, **options()
    )
    assert blender.track_past is False
    replay(setup, blender, int(setup.humans[0]))
    # off, the committed problem is the one built at the decision, on the predicted past
    assert any(not np.allclose(got["x0"], scratch["x0"]) for got, scratch in blender.pairs)
    with pytest.raises(ValueError, match="track_past needs solver='linearised'"):
        plain_blender(setup.movements, networks[:1], setup.table, e_des=setup.e_des, track_past=True)


def test_update_rejudges_the_kept_plan(setup, networks):
    blender = plain_blender(setup.movements, networks, setup.table, e_des=setup.e_des, **options())
    human, n, t = int(setup.humans[0]), setup.library.max_len, 10
    length = min(int(setup.library.length[human]) + 10, n)
    velocity = setup.library.velocity[human]
    predicted = np.zeros((n, 3))
    predicted[t:] = velocity[t:]
    past = np.zeros((n, 3))
    past[:t] = velocity[:t]
    rhs = [blender._sign, blender._z_target, blender.end_speed, blender._delta]
    reference = setup.movements.velocity[0]
    problem = plan_problem(
        t, length, predicted, past, past, reference, 10, 0.01, rhs, setup.subspace, 3000.0, blender.kinematics
    )
    run = blender._linear.start(problem, np.zeros(3 * len(problem["knots"])), blender._z_target,
                                blender._z_clip, blender._delta, blender.delta_pos, 40)  # fmt: skip
    run.run(np.inf)
    assert run.best is not None
    # the same past: the kept plan stays, at its cost, and the run may resume
    run.update(problem)
    assert run.best is not None and run.status == "accepted" and run.finished == (run.done >= run.max_iter)
    # a past that puts the kept plan's gap far beyond δ_pos: it is dropped until an iteration finds another
    shifted = past.copy()
    shifted[: t - 1] += 500.0
    far = with_past(problem, t, length, predicted, shifted, past, reference, 0.01, rhs, setup.subspace, 3000.0)
    run.update(far)
    assert run.best is None and run.status == "fallback"


def test_the_refresh_is_inside_the_tick_budget(setup, networks, monkeypatch):
    """On a clock of 1 ms per reading, a refresh costing 2 ms leaves less room for iterations, not more time."""
    clock = types.SimpleNamespace(now=0.0)

    def read():
        clock.now += 1e-3
        return clock.now

    real = decision.follow_past

    def costly(blender, job, t):
        real(blender, job, t)
        clock.now += 2e-3  # two readings' worth, as an iteration (an odd count would shift the readings' parity)

    monkeypatch.setattr(optimal, "time", types.SimpleNamespace(thread_time=read))
    monkeypatch.setattr(decision, "time", types.SimpleNamespace(thread_time=read))
    monkeypatch.setattr(decision, "follow_past", costly)
    monkeypatch.setattr(LinearisedRun.run, "__kwdefaults__", {"at_least_one": False, "clock": read})
    ticks = {}
    for track in (False, True):
        blender = plain_blender(
            setup.movements, networks, setup.table, e_des=setup.e_des, subspace=setup.subspace,
            **options(track_past=track, time_limit_ms=6.0),
        )  # fmt: skip
        replay(setup, blender, int(setup.humans[0]))
        assert [r for r in blender.results if r.status != "ended"]
        ticks[track] = np.asarray(blender.tick_ms)
    # the budget logic on this clock: a run ends at most one reading past its deadline (an iteration takes two
    # readings, predicted as one), then up to four readings of bookkeeping (the job's time, the check's two, the
    # tick's); the refresh is inside the tick, so it takes room from the iterations, never adds to the tick
    for track in (False, True):
        assert ticks[track].max() <= 6.0 + 1.0 + 4.0 + 1e-9
    assert len(ticks[True]) >= len(ticks[False])  # every tick of a spread solve works on it now


def test_gap_tool_counts_the_plans_failing_at_their_commit():
    rows = planned_vs_emitted(inner_setup(0), 1, time_limit_ms=1000.0, track_past=True)
    assert rows[0]["committed"] >= rows[0]["failing_at_commit"] >= 0 and rows[0]["committed"] > 0
    two = [{**rows[0], "committed": 5, "failing_at_commit": 2}, {**rows[0], "committed": 3, "failing_at_commit": 0}]
    out = summarise(two, 0)
    assert (out["committed"], out["failing_at_commit"]) == (8, 2)
