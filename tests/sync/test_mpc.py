"""Online identification of a Kuramoto group and the model-predictive motion computer (MPCMotion)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cogblocks.data.groups import TABLE2, SyncGroup
from cogblocks.diagrams.sync import MOTIONS, pop_sync
from cogblocks.sim import Diagram, Simulator
from cogblocks.sync import GroupIdentifier, KuramotoGroup, MPCMotion
from cogblocks.sync.group import ring_adjacency
from cogblocks.sync.identification import KuramotoRLS, coupling_regressor


def _identify(group: SyncGroup, n_steps: int, adjacency=None) -> tuple[np.ndarray, np.ndarray]:
    """Phases of a group without L2, and the identifier's estimates at every tick."""
    d = Diagram()
    plant = d.add("group", KuramotoGroup(group.omega, group.gain, adjacency="ring" if adjacency is None else adjacency))
    ident = d.add("ident", GroupIdentifier(group.n, adjacency="ring" if adjacency is None else adjacency))
    d.connect(plant.theta, ident.theta)
    trace = Simulator(d, probes=["ident.omega", "ident.gain", "group.theta"]).run(n_steps=n_steps)
    return trace["ident.omega"], trace["ident.gain"]


@pytest.mark.parametrize("number", [1, 2, 3])
def test_identifier_converges_to_the_true_frequencies_and_gain(number):
    group = TABLE2[number]
    omega, gain = _identify(group, 501)
    np.testing.assert_allclose(omega[-1], group.omega, atol=1e-3)
    assert gain[-1] == pytest.approx(group.gain, rel=1e-3)


def test_identifier_on_another_graph():
    rng = np.random.default_rng(3)
    a = (rng.random((6, 6)) < 0.6).astype(float)
    np.fill_diagonal(a, 0.0)
    group = SyncGroup("random graph", 6, 0.9, tuple(rng.uniform(2.0, 6.0, 6)), 0, 5.0)
    omega, gain = _identify(group, 301, adjacency=a)
    np.testing.assert_allclose(omega[-1], group.omega, atol=1e-3)
    assert gain[-1] == pytest.approx(0.9, rel=1e-3)


def test_rls_solves_the_least_squares_of_the_increments():
    """The recursive estimate equals the batch least squares of the same equations."""
    rng = np.random.default_rng(0)
    n, a = 4, ring_adjacency(4)
    rls = KuramotoRLS(a, prior_weight=0.0)
    rows, ys = [], []
    for _ in range(20):
        seen, now = rng.uniform(0, 2 * np.pi, n), rng.uniform(0, 2 * np.pi, n)
        step = rng.uniform(-0.1, 0.1, n)
        rls.observe(seen, now, np.mod(now + step, 2 * np.pi), 0.01)
        rows.append(np.column_stack([np.eye(n), coupling_regressor(seen, a)]))
        ys.append(step / 0.01)
    batch = np.linalg.lstsq(np.vstack(rows), np.concatenate(ys), rcond=None)[0]
    omega, gain = rls.estimate()
    np.testing.assert_allclose(np.r_[omega, gain], batch, atol=1e-9)


def test_identifier_skips_bad_ticks_and_holds():
    rls = KuramotoRLS(ring_adjacency(3))
    good = np.array([0.1, 0.2, 0.3])
    assert not rls.observe(good, good, np.array([0.1, math.nan, 0.3]), 0.01)
    assert not rls.observe(good, good, np.array([0.1, 1e300, 0.3]), 0.01)
    assert not rls.observe(good, good, good + 1.0, 0.01)  # 100 rad/s: an outlier
    assert rls.count == 0
    assert rls.observe(good, good, good + 0.05, 0.01) and rls.count == 1


def _r_mean(group, motion, n_steps):
    return float(Simulator(pop_sync(group, motion=motion, blender="deliverable")).run(n_steps=n_steps)["r"].mean())


def test_mpc_raises_r_on_group_1():
    group = TABLE2[1]
    without = float(Simulator(pop_sync(group, l2=False)).run(n_steps=1001)["r"].mean())
    mpc = MPCMotion(group.n, group.assisted)
    with_mpc = _r_mean(group, mpc, 1001)
    assert with_mpc > without * 1.05
    # one decision per period; the first waits for 5 identified increments (tick 5 instead of 0)
    assert len(mpc.solve_ms) == 1 + 1000 // mpc.decide_ticks
    assert mpc.plan[0] == pytest.approx(mpc.frequency(1000))


def test_mpc_with_the_true_model_and_by_name():
    group = SyncGroup("short", 4, 1.0, (3.0, 4.0, 5.5, 4.5), 2, 2.0)
    true = MPCMotion(group.n, group.assisted, omega=group.omega, gain=group.gain)
    r_true = _r_mean(group, true, 201)
    r_named = _r_mean(group, MOTIONS["mpc"](group), 201)
    r_without = float(Simulator(pop_sync(group, l2=False)).run(n_steps=201)["r"].mean())
    assert r_true > r_without and r_named > r_without


def test_mpc_reference_is_continuous_after_the_first_plan():
    group = TABLE2[1]
    mpc = MPCMotion(group.n, group.assisted)
    ref = Simulator(pop_sync(group, motion=mpc, blender="deliverable"), probes=["l2.theta_ref"]).run(n_steps=301)[
        "l2.theta_ref"
    ]
    jumps = np.abs(np.angle(np.exp(1j * np.diff(ref[10:]))))
    assert jumps.max() <= 0.01 * 15.0 + 1e-9  # |ω_ref| ≤ 15 rad/s


def test_mpc_refuses_a_step_that_does_not_divide_the_period():
    group = TABLE2[1]
    with pytest.raises(Exception, match="must divide the period"):
        Simulator(pop_sync(group, motion=MPCMotion(group.n, group.assisted, step=0.3), blender="deliverable"))
    with pytest.raises(ValueError, match="together"):
        MPCMotion(3, 0, omega=[1.0, 2.0, 3.0])


def test_the_runners_mpc_plans_on_the_groups_own_graph():
    """``MOTIONS["mpc"]`` (held-out runner, ``pop_sync``) gets the group's adjacency, not a ring."""
    weights = np.array([[0.0, 1.0, 0.5, 0.0], [1.0, 0.0, 0.0, 2.0], [0.5, 0.0, 0.0, 1.0], [0.0, 2.0, 1.0, 0.0]])
    for graph in ("all", weights):
        group = SyncGroup("g", 4, 0.5, (2.0, 2.5, 3.0, 3.5), 1, 2.0, graph=graph)
        np.testing.assert_array_equal(MOTIONS["mpc"](group).adjacency, group.adjacency())


class _CountingSolver:
    """Wraps the planner's IPOPT solver to record the iterations of every call and the tick it ran in."""

    def __init__(self, solver, motion):
        self.solver, self.motion, self.calls = solver, motion, []

    def __call__(self, **kw):
        sol = self.solver(**kw)
        self.calls.append(self.solver.stats()["iter_count"])
        return sol

    def stats(self):
        return self.solver.stats()


def _mpc_with_counter(group, probes=(), **options):
    mpc = MPCMotion(group.n, group.assisted, **options)
    sim = Simulator(pop_sync(group, motion=mpc, blender="deliverable"), probes=list(probes))
    solver, screen = mpc._planner
    counter = _CountingSolver(solver, mpc)
    mpc._planner = (counter, screen)
    return mpc, sim, counter


def test_mpc_spreads_each_solve_over_the_period_and_its_plan_beats_the_candidates():
    group = TABLE2[1]
    mpc, sim, counter = _mpc_with_counter(group, probes=["l2.theta_ref"], iterations_per_tick=2, max_iter=20)
    ref = sim.run(n_steps=301)["l2.theta_ref"]
    assert counter.calls and max(counter.calls) <= 2  # no tick runs more than a chunk
    # every decision's solve ends (converged or 20 iterations) well inside its 50-tick period
    assert mpc.fallbacks == 0 and len(mpc.solve_ms) == 1 + 300 // 50
    assert len(mpc.tick_ms) == len(counter.calls) + len(mpc.solve_ms)  # decision ticks screen, the others solve
    # within a period θ_ref turns at the one committed frequency, whatever the chunks do to the later knots
    step = np.angle(np.exp(1j * np.diff(ref)))
    for k0 in range(50, 300, 50):
        np.testing.assert_allclose(step[k0 : k0 + 50], step[k0], atol=1e-9)
    # the plan kept is the one whose cost the block recorded, and that is no worse than the candidate's
    _, screen = mpc._planner
    cost = float(screen(np.column_stack([mpc.plan[1:]] * mpc.candidates), mpc.solve_par).full()[0, 0])
    assert cost == pytest.approx(mpc.solve_cost, abs=1e-12)


def test_mpc_solve_cut_short_by_its_period_is_a_fallback_and_the_candidate_plan_stands():
    group = TABLE2[1]
    # a 2-tick period with one iteration per tick leaves one chunk per decision: most solves are cut short
    mpc, sim, counter = _mpc_with_counter(group, decide_every=0.02, step=0.02, iterations_per_tick=1, max_iter=20)
    sim.run(n_steps=41)
    assert max(counter.calls) <= 1
    converged = sum(1 for c in counter.calls if c < 1)  # a chunk that stopped before its one iteration converged
    cut_short = len(mpc.solve_ms) - 1 - converged  # the last decision's solve is still running
    assert len(mpc.solve_ms) >= mpc.fallbacks >= cut_short > 0
    assert np.isfinite(mpc.plan).all()
