"""The noisy group plant: phase noise (Euler–Maruyama), an Ornstein–Uhlenbeck frequency drift, common random numbers."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from cogblocks.blocks import Playback, Probe
from cogblocks.data.groups import random_groups
from cogblocks.diagrams.sync import pop_sync
from cogblocks.sim import Diagram, Simulator
from cogblocks.sync.group import KuramotoGroup

OMEGA = np.array([2.0, 3.5, 4.0, 5.5])
DT = 0.01


def _run(n_steps: int, *, theta_l2: np.ndarray | None = None, **options) -> np.ndarray:
    """The phases before each tick (n_steps + 1 rows); with ``theta_l2``, participant 1 is assisted and shown it."""
    d = Diagram()
    assisted = None if theta_l2 is None else 1
    group = d.add("group", KuramotoGroup(OMEGA, options.pop("gain", 0.8), assisted=assisted, **options))
    d.add("theta", Probe())
    d.connect(group.theta, "theta.u")
    if theta_l2 is not None:
        shown = d.add("shown", Playback(theta_l2, unit="rad", wrapped=True))
        d.connect(shown.y, group.theta_l2)
    return Simulator(d).run(n_steps=n_steps + 1)["theta"]


def _increments(theta: np.ndarray, seen: np.ndarray, gain: float) -> np.ndarray:
    """What each tick added beyond the noise-free Euler step, computed here on the ring (wrapped to (−π, π])."""
    ring = np.roll(np.eye(len(OMEGA)), 1, axis=1) + np.roll(np.eye(len(OMEGA)), -1, axis=1)
    pull = (ring * np.sin(seen[:-1, None, :] - seen[:-1, :, None])).sum(axis=2)
    step = np.diff(theta, axis=0) - DT * (OMEGA + gain * pull)
    return np.mod(step + np.pi, 2 * np.pi) - np.pi


def test_without_noise_the_plant_is_todays_bit_for_bit_and_holds_no_noise_state():
    plain = KuramotoGroup(OMEGA, 0.8)
    zero = KuramotoGroup(OMEGA, 0.8, noise=0.0, drift_spread=[0.0] * 4, drift_tau=3.0, seed=7)
    assert set(zero.state_dict()["state"]) == set(plain.state_dict()["state"]) == {"phase"}
    np.testing.assert_array_equal(_run(2000), _run(2000, noise=0.0, drift_spread=0.0, seed=7))
    assert not np.any(zero.noise_path(50))


def test_the_noise_is_the_same_whatever_l2_shows_common_random_numbers():
    """The same seed, two different θ_L2 inputs: each tick's increment beyond the noise-free step (computed here
    from the phases each participant saw) is the same, and is the block's own noise_path."""
    gain, n = 0.8, 600
    options = {"noise": [0.1, 0.3, 0.0, 0.5], "drift_spread": 0.1, "drift_tau": 2.0, "seed": 11}
    path = KuramotoGroup(OMEGA, gain, **options).noise_path(n)
    for shown in (np.zeros(n + 1), np.linspace(0.0, 40.0, n + 1)):
        theta = _run(n, theta_l2=np.mod(shown, 2 * np.pi), gain=gain, **options)
        seen = theta.copy()
        seen[:, 1] = np.mod(shown, 2 * np.pi)
        np.testing.assert_allclose(_increments(theta, seen, gain), path, atol=1e-9)
    assert np.abs(path[:, 2]).max() > 0.0  # participant 2 has no phase noise, but drifts


def test_another_seed_is_another_draw_and_the_same_seed_the_same():
    first = KuramotoGroup(OMEGA, 0.8, noise=0.2, seed=1).noise_path(100)
    np.testing.assert_array_equal(first, KuramotoGroup(OMEGA, 0.8, noise=0.2, seed=1).noise_path(100))
    assert not np.allclose(first, KuramotoGroup(OMEGA, 0.8, noise=0.2, seed=2).noise_path(100))


def test_phase_increments_have_variance_sigma_squared_dt():
    """Uncoupled, drift-free: the increments are σ_i √dt ξ. 20 000 ticks: the variance's relative standard error
    is 1 %, the margin 5 %; the means are within 5 standard errors of 0."""
    sigma = np.array([0.05, 0.2, 0.35, 0.5])
    n = 20_000
    theta = _run(n, gain=0.0, noise=sigma, seed=3)
    step = _increments(theta, theta, 0.0)
    np.testing.assert_allclose(step.var(axis=0), sigma**2 * DT, rtol=0.05)
    assert np.all(np.abs(step.mean(axis=0)) < 5 * sigma * np.sqrt(DT / n))


def test_the_drift_is_an_ou_process_with_its_time_constant_and_spread():
    """δ_i = increment / dt from the noise path: autocorrelation exp(−lag/τ) at lags τ/2, τ, 2τ, and a stationary
    standard deviation of spread·|ω_i|. τ = 0.5 s over 3000 s (6000 time constants per participant, 4 pooled)."""
    tau, spread = 0.5, np.array([0.05, 0.1, 0.1, 0.15])
    plant = KuramotoGroup(OMEGA, 0.8, drift_spread=spread, drift_tau=tau, seed=5)
    drift = plant.noise_path(300_000) / DT
    drift = drift[1000:]  # past the start at 0 (20 time constants)
    np.testing.assert_allclose(drift.std(axis=0), spread * OMEGA, rtol=0.08)
    z = (drift - drift.mean(axis=0)) / drift.std(axis=0)
    for lag_s in (0.25, 0.5, 1.0):
        lag = round(lag_s / DT)
        rho = float((z[:-lag] * z[lag:]).mean())
        assert rho == pytest.approx(np.exp(-lag_s / tau), abs=0.04)


def test_the_drift_starts_at_the_groups_frequencies():
    path = KuramotoGroup(OMEGA, 0.8, drift_spread=0.1, seed=5).noise_path(3)
    assert not np.any(path[0])  # δ(0) = 0: the first tick has no drift and no phase noise here
    assert np.any(path[1])


@pytest.mark.parametrize("via", ["dict", "file"])
def test_a_restored_noisy_run_continues_bit_for_bit(tmp_path, via):
    """The generator and the drift are block state: a snapshot, then 300 ticks; restored elsewhere, the same."""
    group = random_groups(1, "validation", 3, noise=True)[0]
    sim = Simulator(pop_sync(group, motion="mean"))
    sim.run(n_steps=250)
    state = sim.state_dict()
    assert {"rng", "drift"} <= set(state["blocks"]["group"]["state"])
    if via == "file":
        sim.save_state(tmp_path / "snap.npz")
    first = sim.run(n_steps=300)
    other = Simulator(pop_sync(group, motion="mean"))
    other.run(n_steps=17)
    if via == "file":
        other.load_state(tmp_path / "snap.npz")
    else:
        other.load_state_dict(state)
    np.testing.assert_array_equal(first["r"], other.run(n_steps=300)["r"])
    other.reset()  # back to the first draw
    fresh = Simulator(pop_sync(group, motion="mean")).run(n_steps=250)["r"]
    np.testing.assert_array_equal(other.run(n_steps=250)["r"], fresh)


def test_a_noisy_group_in_pop_sync_is_noisy_and_reproducible():
    group = dataclasses.replace(random_groups(1, "validation", 0, noise=True)[0], duration=1.0)
    without = Simulator(pop_sync(group, l2=False)).run(n_steps=101)["r"]
    noise_free = Simulator(pop_sync(dataclasses.replace(group, noise=None), l2=False)).run(n_steps=101)["r"]
    assert not np.allclose(without, noise_free)
    again = Simulator(pop_sync(group, l2=False)).run(n_steps=101)["r"]
    np.testing.assert_array_equal(without, again)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"noise": -0.1}, "noise must be a number >= 0 or 4 numbers >= 0"),
        ({"noise": [0.1, 0.2]}, "noise must be a number >= 0 or 4 numbers >= 0"),
        ({"drift_spread": [0.1, -0.1, 0.0, 0.0]}, "drift_spread must be a number >= 0"),
        ({"drift_tau": 0.0}, "drift_tau must be > 0 s"),
        ({"noise": 0.1, "seed": -1}, "seed must be None, an int >= 0"),
    ],
)
def test_bad_noise_options_are_refused_by_name(options, message):
    with pytest.raises(ValueError, match=message):
        KuramotoGroup(OMEGA, 0.8, **options)
