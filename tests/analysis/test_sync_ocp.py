"""Whole-run optimal control of the alteration: its model against the blocks, and its value against brute force."""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest

from cogblocks.analysis.sync_ocp import (
    alteration_model,
    alteration_rollout,
    known_noise_tick_model,
    resimulate,
    windowed_control_bound,
)
from cogblocks.data.groups import TABLE2, GroupNoise, SyncGroup, random_groups
from cogblocks.diagrams.sync import pop_sync
from cogblocks.evaluation.sync_bound import upper_bound
from cogblocks.sim import Simulator
from cogblocks.sync.guarded import GuardedPacingMotion
from cogblocks.sync.model import DT, BlenderParams, SyncModel, order_parameter
from cogblocks.sync.whole_run import CHUNK

# three participants, far apart in frequency (unlocked): the alteration matters from the first ticks
GROUP = SyncGroup("tiny", 3, 0.4, (1.0, 3.5, 6.0), 1, 1.0, graph="all")
TICKS = round(GROUP.duration / DT) + 1


def _roll(group: SyncGroup, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return alteration_rollout(alteration_model(group), np.r_[np.zeros(group.n), BlenderParams().lam_max], s)


def test_doing_nothing_is_the_run_without_l2():
    _, r = _roll(GROUP, np.zeros(TICKS))
    without = Simulator(pop_sync(GROUP, l2=False)).run(n_steps=TICKS)["r"]
    np.testing.assert_allclose(r, without, atol=1e-12)


def test_model_of_any_alteration_is_the_blocks():
    """Random fractions of λ, turned into θ_ref and re-simulated through the blocks, give the model's r."""
    s = np.random.default_rng(0).uniform(-1.0, 1.0, TICKS)
    states, r = _roll(GROUP, s)
    theta_ref = states[:, GROUP.assisted] + states[:, GROUP.n] * s
    assert resimulate(GROUP, theta_ref) == pytest.approx(float(r.mean()), abs=1e-12)
    assert np.all(states[:, GROUP.n] <= BlenderParams().lam_max + 1e-12)


def _brute_force(group: SyncGroup, blocks: int, levels: np.ndarray) -> float:
    """Best mean r over alterations piecewise constant on ``blocks`` blocks at ``levels`` × λ, on SyncModel."""
    plans = np.array(list(itertools.product(levels, repeat=blocks)))
    s = np.repeat(plans, -(-TICKS // blocks), axis=1)[:, :TICKS]
    model = SyncModel.from_group(group)
    theta = np.zeros((len(plans), group.n))
    lam = np.full(len(plans), model.blender.lam_max)
    total = np.zeros(len(plans))
    for k in range(TICKS):
        reference = theta[:, group.assisted] + lam * s[:, k]  # the blender clips it to exactly λ · s
        seen, _, lam = model.blend(theta, reference, lam)
        total += order_parameter(seen)
        theta, _ = model.advance(theta, seen, np.zeros(len(plans)), np.zeros(len(plans)))
    return float(total.max() / TICKS)


def test_bound_beats_brute_force_and_its_starts():
    found = windowed_control_bound(GROUP, window=0.5, tail=0.25, knot=0.05, details=True)
    brute = _brute_force(GROUP, 4, np.linspace(-1.0, 1.0, 5))
    assert found["r"] >= brute - 1e-9
    assert found["r"] == pytest.approx(found["r_model"], abs=1e-12)
    assert found["r"] >= max(found["starts"].values()) - 1e-12
    without = float(Simulator(pop_sync(GROUP, l2=False)).run(n_steps=TICKS)["r"].mean())
    mean = float(Simulator(pop_sync(GROUP, motion="mean", blender="deliverable")).run(n_steps=TICKS)["r"].mean())
    assert found["starts"]["none"] == pytest.approx(without, abs=1e-12)
    assert found["starts"]["mean"] == pytest.approx(mean, abs=1e-12)
    assert resimulate(GROUP, found["theta_ref"]) == found["r"]


def test_default_policy_start_is_its_closed_loop():
    """``guard=True``: the start is pop_sync's default policy run independently, so the bound is at least its r."""
    group = dataclasses.replace(TABLE2[1], duration=8.0)  # its first decision applies at 4 s
    ticks = round(group.duration / DT) + 1
    motion = GuardedPacingMotion.for_trial(group.n, group.assisted, adjacency=group.graph, end=group.duration)
    guard = float(Simulator(pop_sync(group, motion=motion, blender="deliverable")).run(n_steps=ticks)["r"].mean())
    without = float(Simulator(pop_sync(group, l2=False)).run(n_steps=ticks)["r"].mean())
    found = windowed_control_bound(group, pace=False, guard=True, max_iter=5, details=True)
    assert guard > without + 0.01  # the policy acts within the run: the start is not doing nothing
    assert found["starts"]["guard"] == pytest.approx(guard, abs=1e-12)
    assert found["r"] >= guard - 1e-12
    assert "guard" not in windowed_control_bound(group, pace=False, max_iter=5, details=True)["starts"]


def test_further_passes_only_raise_the_whole_run_objective():
    """Each pass starts from the one before and keeps a move only if the whole run's mean r rises."""
    group = dataclasses.replace(random_groups(1, "train", 0)[0], duration=5.0)
    one = windowed_control_bound(group, pace=False, max_iter=10, details=True)
    three = windowed_control_bound(
        group, pace=False, max_iter=10, passes=((2.0, 2.0, 0.25), (1.0, 1.0, 0.25)), details=True
    )
    assert three["sweeps"][0] == one["sweeps"][0] == one["r_model"]
    assert np.all(np.diff(three["sweeps"]) >= 0.0) and three["sweeps"][-1] > one["r_model"]
    assert three["r"] == pytest.approx(three["r_model"], abs=1e-10)  # re-simulated through the blocks
    assert three["windows"] == one["windows"] + 3 + 6  # 501 ticks: 3 windows of 2 s, 6 of 1 s
    assert upper_bound(group, max_iter=10, thorough=True) >= three["r"] - 1e-12


def test_bad_arguments():
    with pytest.raises(ValueError, match="knot"):
        windowed_control_bound(GROUP, window=0.5, knot=0.3)
    with pytest.raises(ValueError, match=r"knot \(0.3 s\) must divide window \(1.0 s\)"):
        windowed_control_bound(GROUP, passes=((1.0, 1.0, 0.3),))
    with pytest.raises(ValueError, match="adjacency must be 3x3"):
        windowed_control_bound(GROUP, adjacency=np.zeros((2, 2)))
    with pytest.raises(ValueError, match="adjacency must be 3x3"):
        resimulate(GROUP, np.zeros(5), adjacency=np.zeros((4, 4)))


NOISY = dataclasses.replace(
    GROUP, noise=GroupNoise(sigma=(0.3, 0.1, 0.5), drift_spread=(0.1, 0.15, 0.05), drift_tau=5.0, seed=9)
)


def test_the_known_noise_model_of_any_alteration_is_the_noisy_blocks():
    """The clairvoyant model (noise draw as a known input) against the noisy plant driven by the same reference."""
    s = np.random.default_rng(2).uniform(-1.0, 1.0, TICKS)
    tick = known_noise_tick_model(NOISY, NOISY.adjacency(), BlenderParams(), TICKS)
    x0 = np.r_[np.zeros(NOISY.n), BlenderParams().lambda_max, 0.0]
    states, r = alteration_rollout(tick.mapaccum("roll", CHUNK), x0, s)
    np.testing.assert_array_equal(states[:, -1], np.arange(TICKS))  # the tick counter the lookup reads
    theta_ref = states[:, NOISY.assisted] + states[:, NOISY.n] * s
    assert r.mean() == pytest.approx(resimulate(NOISY, theta_ref), abs=1e-9)
    _, r_free = _roll(GROUP, s)
    assert abs(r.mean() - r_free.mean()) > 1e-3  # the noise matters on this group


def test_the_clairvoyant_bound_is_above_the_noisy_policies_and_the_run_without_l2():
    found = windowed_control_bound(NOISY, pace=False, details=True)
    assert found["r_model"] == pytest.approx(found["r"], abs=1e-9)
    without = Simulator(pop_sync(NOISY, l2=False)).run(n_steps=TICKS)["r"].mean()
    mean_rule = Simulator(pop_sync(NOISY, motion="mean", blender="deliverable")).run(n_steps=TICKS)["r"].mean()
    assert found["starts"]["mean_closed_loop"] == pytest.approx(mean_rule, abs=1e-9)
    assert found["r"] >= max(without, mean_rule) - 1e-9
    assert upper_bound(NOISY, pace=False) == pytest.approx(found["r"], abs=1e-12)  # no noise-free scan mixed in
    assert found["r"] != pytest.approx(windowed_control_bound(GROUP, pace=False), abs=1e-4)
