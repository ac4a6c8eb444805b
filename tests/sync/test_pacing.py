"""The pacing motion computer (PacingMotion): its predictions, its choice, its identification and its bad data."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cogblocks.data.groups import TABLE2, SyncGroup
from cogblocks.diagrams.sync import MOTIONS, pop_sync
from cogblocks.sim import Diagram, Simulator
from cogblocks.sync import PacingMotion
from cogblocks.sync.group import ring_adjacency
from cogblocks.sync.model import BlenderParams
from cogblocks.sync.pacing import MEAN, NONE, PACE, predicted_order

BLENDER = BlenderParams()


def brute_force(theta, lam, omega, gain, a, assisted, kind, value, anchor, step, steps):
    """One candidate simulated with scalar loops (an independent transcription of the closed loop)."""
    n = len(theta)
    theta, total = [float(x) for x in theta], 0.0
    for s in range(steps):
        l0 = theta[assisted]
        if kind == PACE:
            ref = anchor + value * s * step
        elif kind == MEAN:
            ref = math.atan2(
                sum(math.sin(theta[j]) for j in range(n) if j != assisted),
                sum(math.cos(theta[j]) for j in range(n) if j != assisted),
            )
        else:
            ref = l0
        d = (ref - l0 + math.pi) % (2 * math.pi) - math.pi
        if kind == MEAN and abs(d) > value:  # gated: no alteration while the mean is farther than the gate
            d = 0.0
        shift = min(max(d, -lam), lam)
        seen = list(theta)
        seen[assisted] = l0 + shift
        total += abs(sum(complex(math.cos(x), math.sin(x)) for x in seen)) / n
        lam_inf = max(0.0, 1.0 - abs(shift) / BLENDER.e_max) * (BLENDER.lam_max - BLENDER.lam_min)
        lam_inf += BLENDER.lam_min
        lam -= step * (BLENDER.kappa_plus if lam <= lam_inf else BLENDER.kappa_minus) * (lam - lam_inf)
        theta = [
            theta[i] + step * (omega[i] + gain * sum(a[i][j] * math.sin(seen[j] - seen[i]) for j in range(n)))
            for i in range(n)
        ]
    return total / steps


def test_predicted_order_equals_a_scalar_simulation_of_each_candidate():
    rng = np.random.default_rng(1)
    n, assisted = 4, 2
    a = rng.uniform(0.0, 1.5, (n, n)) * (rng.random((n, n)) < 0.7)  # weighted, directed
    np.fill_diagonal(a, 0.0)
    theta, omega, gain, lam = rng.uniform(0, 2 * np.pi, n), rng.uniform(1.0, 4.0, n), 0.8, 1.1
    kinds = np.array([NONE, MEAN, MEAN, PACE, PACE, PACE])
    freqs = np.array([0.0, math.pi, 1.5, 1.0, 2.5, 4.0])  # mean's gate, pace's frequency
    anchors = np.array([0.0, 0.0, 0.0, 0.3, 5.0, -2.0])
    got = predicted_order(
        theta, lam, (omega, gain), a, assisted, BLENDER, (kinds, freqs, anchors), step=0.05, steps=120
    )
    want = [
        brute_force(theta, lam, omega, gain, a, assisted, *c, 0.05, 120)
        for c in zip(kinds, freqs, anchors, strict=True)
    ]
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    assert np.ptp(want) > 1e-3  # the candidates really differ


def _compiled(block: PacingMotion) -> PacingMotion:
    """``block`` set up at the 10 ms tick (as in a diagram)."""
    _run_inputs(block, np.zeros((1, block.n)), np.full(1, math.pi / 2))
    return block


def test_the_choice_is_the_best_candidate_of_a_brute_force_simulation():
    """With no margins the block takes the candidate that an independent simulation predicts best."""
    rng = np.random.default_rng(4)
    n, assisted = 3, 0
    a = ring_adjacency(n)
    omega, gain = np.array([2.0, 2.9, 3.6]), 0.4
    block = _compiled(PacingMotion(n, assisted, horizon=3.0, frequencies=5, margin=0.0, switch_margin=0.0))
    for _ in range(3):
        theta, lam = rng.uniform(0, 2 * np.pi, n), rng.uniform(BLENDER.lam_min, BLENDER.lam_max)
        ref = float(theta[assisted])  # the block does nothing yet: θ_ref = θ_L0, θ̃ = θ
        best, (kinds, freqs, anchors), _ = block.plan(theta, theta.copy(), lam, ref, (omega, gain))
        # the first 10 ms step is shared, then every candidate runs 60 steps of 50 ms
        pull = np.array([sum(a[i, j] * math.sin(theta[j] - theta[i]) for j in range(n)) for i in range(n)])
        theta_next = theta + 0.01 * (omega + gain * pull)
        lam_next = lam - 0.01 * BLENDER.kappa_plus * (lam - BLENDER.lam_max)
        scores = [
            brute_force(theta_next, lam_next, omega, gain, a, assisted, *c, 0.05, 60)
            for c in zip(kinds, freqs, anchors, strict=True)
        ]
        assert best == int(np.argmax(scores))
        assert len(kinds) == 1 + 3 + 2 * 5 and kinds[0] == NONE and list(kinds[1:4]) == [MEAN] * 3


def test_nothing_is_done_when_no_candidate_is_predicted_clearly_better():
    # a locked group at its fixed point: doing nothing keeps r = 1; any alteration can only lower it
    n, omega = 4, np.full(4, 3.0)
    block = _compiled(PacingMotion(n, 1, horizon=2.0, margin=0.0, switch_margin=0.0))
    theta = np.full(n, 1.0)
    best, (kinds, _, _), scores = block.plan(theta, theta.copy(), math.pi / 2, 1.0, (omega, 1.0))
    assert kinds[best] == NONE and scores[0] == pytest.approx(1.0, abs=1e-12)
    assert np.all(scores[kinds == PACE] < 1.0 - 1e-6)
    # where the mean helps, a margin larger than its predicted gain still leaves the group alone
    theta = np.array([0.0, 2.0, 0.1, -0.1])
    best, (kinds, _, _), scores = block.plan(theta, theta.copy(), math.pi / 2, 2.0, (omega, 0.05))
    assert kinds[best] != NONE and scores[best] > scores[0]
    gain = float(scores.max() - scores[0])
    cautious = _compiled(PacingMotion(n, 1, horizon=2.0, margin=gain + 1e-3))
    best, _, _ = cautious.plan(theta, theta.copy(), math.pi / 2, 2.0, (omega, 0.05))
    assert best == 0


def _closed_loop(group: SyncGroup, block: PacingMotion, seconds: float):
    probes = {"ref": "l2.theta_ref", "l0": "l2.theta_l0", "l2": "l2.theta_l2"}
    return Simulator(pop_sync(group, motion=block, blender="deliverable"), probes=probes).run(
        n_steps=round(seconds / 0.01) + 1
    )


def test_it_identifies_the_group_online_and_decides_every_period():
    group = TABLE2[1]
    block = PacingMotion(group.n, group.assisted, decide_every=1.0, horizon=5.0)
    _closed_loop(group, block, 4.0)
    omega, gain = block.model()
    np.testing.assert_allclose(omega, group.omega, atol=1e-3)  # the prior biases by ~1e-5
    assert gain == pytest.approx(group.gain, rel=1e-3)
    # decisions at ticks 100, 200, 300, 400 (the model is trusted after 100 increments)
    assert len(block.choices) == len(block.decide_ms) == 4


def test_doing_nothing_leaves_the_group_exactly_as_without_l2():
    """Until the model is trusted the block emits θ_L0: the group runs exactly as without L2."""
    group = TABLE2[2]
    block = PacingMotion(group.n, group.assisted, min_ticks=10**6)
    trace = _closed_loop(group, block, 3.0)
    without = Simulator(pop_sync(group, l2=False)).run(n_steps=301)
    np.testing.assert_array_equal(trace["ref"], trace["l0"])
    np.testing.assert_array_equal(trace["r"], without["r"])
    assert block.choices == []


def _run_inputs(block: PacingMotion, theta: np.ndarray, lam: np.ndarray) -> np.ndarray:
    d = Diagram()
    m = d.add("m", block)
    d.expose_input("theta", m.theta)
    d.expose_input("lam", m.lam)
    trace = Simulator(d, probes={"ref": "m.theta_ref"}).run(n_steps=len(theta), inputs={"theta": theta, "lam": lam})
    return trace["ref"]


def test_bad_data_policy():
    """A bad tick identifies and decides nothing; θ_ref holds, or keeps pacing."""
    n, ticks = 3, 60
    t = np.arange(ticks)[:, None] * 0.01
    theta = np.mod(np.array([2.0, 3.0, 4.0]) * t + np.array([0.0, 1.0, 2.5]), 2 * np.pi)
    lam = np.full(ticks, 1.0)
    theta[20, 1] = np.nan
    theta[30, 0] = 1e300
    lam[40] = np.inf
    block = PacingMotion(n, 0, start="mean", min_ticks=10**6)
    ref = _run_inputs(block, theta, lam)
    assert np.isfinite(ref).all()
    for k in (20, 30):  # phases unusable: the mean is not recomputed
        assert ref[k] == ref[k - 1]
    # λ = inf is not a bad phase: θ_ref follows the mean, but no increment is identified around the bad ticks
    want = np.arctan2(np.sin(theta[40, 1:]).sum(), np.cos(theta[40, 1:]).sum()) % (2 * np.pi)
    assert ref[40] == pytest.approx(want, abs=1e-12)
    # 59 increments, less those ending at or starting from a bad phase (19→20, 20→21, 29→30, 30→31) or λ (40, 41)
    assert block.count == 59 - 6
    # pacing: the reference keeps its frequency through a bad tick
    pacer = PacingMotion(n, 0, min_ticks=10**6)
    d = Diagram()
    m = d.add("m", pacer)
    d.expose_input("theta", m.theta)
    d.expose_input("lam", m.lam)
    sim = Simulator(d, probes={"ref": "m.theta_ref"})
    sim.run(n_steps=1, inputs={"theta": theta[:1], "lam": lam[:1]})
    pacer.mode, pacer.value = PACE, 3.0  # as a decision would leave it
    ref = sim.run(n_steps=29, inputs={"theta": theta[1:30], "lam": lam[1:30]})["ref"]
    np.testing.assert_allclose(np.diff(np.unwrap(ref)), 0.03, atol=1e-12)


def test_the_retired_name_pace_still_builds_the_block_for_the_groups_graph_and_names_replan():
    group = SyncGroup("all", 4, 0.5, (2.0, 2.5, 3.0, 3.5), 1, 2.0, graph="all")
    with pytest.warns(DeprecationWarning, match="motion computer 'pace' is retired: use 'replan'"):
        block = MOTIONS["pace"](group)
    assert isinstance(block, PacingMotion)
    np.testing.assert_array_equal(block.adjacency, group.adjacency())


def test_constructor_checks():
    with pytest.raises(ValueError, match="start must be one of"):
        PacingMotion(3, 0, start="pace")
    with pytest.raises(ValueError, match="horizon must be"):
        PacingMotion(3, 0, horizon=0.0)
