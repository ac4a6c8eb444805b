"""Closed loop of the Social Connectedness PoP: Table 3's baseline, and the batched env against a plain loop."""

from __future__ import annotations

import cmath
import math

import numpy as np
import pytest

from cogblocks.blocks.angles import wrap_pi
from cogblocks.data.groups import TABLE2, SyncGroup
from cogblocks.sync import SyncModel, ring_adjacency
from cogblocks.sync.model import wrap
from cogblocks.sync.motion import ACTIONS, HOLD_ACTION, l3_observation
from cogblocks.training.sync_env import SyncEnv, evaluate, order_parameter_without_l2


def reference_loop(group: SyncGroup, actions: np.ndarray, l2: bool) -> dict[str, np.ndarray]:
    """The closed loop written tick by tick with scalars, straight from the equations."""
    two_pi, dt, n, a = 2 * math.pi, 0.01, group.n, group.assisted
    lam_max = math.pi / 2
    lam_min = e_max = 0.3 * math.pi / 2
    neighbours = [[(i - 1) % n, (i + 1) % n] for i in range(n)]

    def to_2pi(x: float) -> float:
        return x % two_pi

    def to_pi(x: float) -> float:
        return math.pi - (math.pi - x) % two_pi

    theta, theta_l3, lam, omega_l3 = [0.0] * n, 0.0, lam_max, sum(group.omega) / n
    out: dict[str, list] = {key: [] for key in ("theta", "theta_l3", "lam", "r", "obs", "alteration")}
    for k in range(len(actions) + 1):
        q = sum(cmath.exp(1j * to_pi(theta_l3 - theta[j])) for j in range(n) if j != a) / (n - 1)
        out["obs"].append([cmath.phase(q), 1 - abs(q), omega_l3])
        seen = list(theta)
        alteration = 0.0
        if l2:
            theta_l0 = theta[a]
            theta_l2 = to_2pi(theta_l0 + min(max(to_pi(theta_l3 - theta_l0), -lam), lam))
            alteration = to_pi(theta_l2 - theta_l0)
            lam_inf = max(0.0, 1 - abs(alteration / e_max)) * (lam_max - lam_min) + lam_min
            kappa = 1.0 if lam <= lam_inf else 2.5
            lam_next = lam - dt * kappa * (lam - lam_inf)
            seen[a] = theta_l2
        for key, value in (("theta", list(theta)), ("theta_l3", theta_l3), ("lam", lam), ("alteration", alteration)):
            out[key].append(value)
        out["r"].append(abs(sum(cmath.exp(1j * x) for x in seen) / n))
        if k == len(actions):
            break
        omega_l3 = min(max(omega_l3 + ACTIONS[actions[k]], -15.0), 15.0)
        pull_l3 = sum(math.sin(theta[j] - theta_l3) for j in neighbours[a])
        theta = [
            to_2pi(
                theta[i] + dt * (group.omega[i] + group.gain * sum(math.sin(seen[j] - seen[i]) for j in neighbours[i]))
            )
            for i in range(n)
        ]
        theta_l3 = to_2pi(theta_l3 + dt * (omega_l3 + group.gain * pull_l3))
        if l2:
            lam = lam_next
    return {key: np.array(value) for key, value in out.items()}


def run_env(env: SyncEnv, actions: np.ndarray) -> dict[str, np.ndarray]:
    """Record the batched env's state tick by tick under fixed actions of shape (ticks, B)."""
    out: dict[str, list] = {key: [] for key in ("theta", "theta_l3", "lam", "r", "obs", "alteration")}
    env.reset()
    for k in range(len(actions) + 1):
        for key, value in (
            ("theta", env.theta),
            ("theta_l3", env.theta_l3),
            ("lam", env.lam),
            ("r", env.r),
            ("obs", env.observation),
            ("alteration", env.alteration),
        ):
            out[key].append(value.copy())
        if k < len(actions):
            env.step(actions[k])
    return {key: np.array(value) for key, value in out.items()}


@pytest.mark.parametrize(("group_number", "expected"), [(1, 0.76), (2, 0.47), (3, 0.61)])
def test_without_l2_reproduces_table3(group_number: int, expected: float) -> None:
    assert round(order_parameter_without_l2(TABLE2[group_number]), 2) == expected


@pytest.mark.parametrize("group_number", [1, 3])
@pytest.mark.parametrize("l2", [True, False])
def test_batched_env_matches_plain_loop(group_number: int, l2: bool) -> None:
    group = TABLE2[group_number]
    ticks, batch = 300, 3
    # Bang-bang runs drive the reference across the blender's whole range, the random one anywhere.
    rng = np.random.default_rng(7)
    actions = np.stack(
        [np.full(ticks, len(ACTIONS) - 1), np.zeros(ticks, dtype=int), rng.integers(len(ACTIONS), size=ticks)], axis=1
    )
    env = run_env(SyncEnv.from_group(group, batch, l2=l2), actions)
    if l2:  # the saturation and both branches of the lambda dynamics are exercised
        assert env["lam"].min() < 0.6 and np.any(np.diff(env["lam"], axis=0) > 0)
        assert np.any(np.isclose(np.abs(env["alteration"]), env["lam"]) & (env["lam"] < 1.5))
    for episode in range(batch):
        ref = reference_loop(group, actions[:, episode], l2)
        np.testing.assert_allclose(wrap_pi(env["theta"][:, episode] - ref["theta"]), 0.0, atol=1e-12)
        np.testing.assert_allclose(wrap_pi(env["theta_l3"][:, episode] - ref["theta_l3"]), 0.0, atol=1e-12)
        np.testing.assert_allclose(wrap_pi(env["obs"][:, episode, 0] - ref["obs"][:, 0]), 0.0, atol=1e-12)
        for key in ("r", "alteration") + (("lam",) if l2 else ()):
            np.testing.assert_allclose(env[key][:, episode], ref[key], rtol=0, atol=1e-12, err_msg=key)
        np.testing.assert_allclose(env["obs"][:, episode, 1:], ref["obs"][:, 1:], rtol=0, atol=1e-12)


def test_step_reward_is_next_order_parameter_and_episode_ends() -> None:
    env = SyncEnv.from_group(TABLE2[1], 2)
    r_sum = env.r.copy()
    done = False
    while not done:
        _, reward, done = env.step(np.array([HOLD_ACTION, 0]))
        r_sum += reward
    assert env.k == 1000
    np.testing.assert_allclose(env.mean_order_parameter, r_sum / 1001)
    with pytest.raises(RuntimeError):
        env.step(np.array([HOLD_ACTION, HOLD_ACTION]))


def test_observation_values() -> None:
    # Alone with one other participant: q is the unit phasor of the wrapped offset.
    np.testing.assert_allclose(l3_observation(0.1, np.array([2 * np.pi - 0.1]), 4.0), [0.2, 0.0, 4.0], atol=1e-15)
    # Others at 0 and pi/2, L3 halfway: on their circular mean, |q| = cos(pi/4).
    np.testing.assert_allclose(
        l3_observation(np.pi / 4, np.array([0.0, np.pi / 2]), -1.0), [0.0, 1 - np.sqrt(0.5), -1.0], atol=1e-15
    )
    batched = l3_observation(np.zeros(4), np.zeros((4, 6)), np.arange(4.0))
    assert batched.shape == (4, 3)
    np.testing.assert_array_equal(batched[:, 2], np.arange(4.0))


def test_wraps() -> None:
    assert wrap_pi(np.pi) == np.pi
    assert wrap_pi(-np.pi) == np.pi
    assert wrap_pi(3 * np.pi / 2) == pytest.approx(-np.pi / 2)
    assert 0 <= wrap(-0.5) < 2 * np.pi
    np.testing.assert_array_equal(ring_adjacency(4).sum(axis=1), 2)


def test_groups_are_table2_with_zero_based_indices() -> None:
    assert [(g.n, g.assisted, g.duration) for g in TABLE2.values()] == [(5, 3, 10.0), (7, 5, 300.0), (7, 5, 300.0)]
    assert TABLE2[1].omega[TABLE2[1].assisted] == 9.91
    assert TABLE2[2].gain == pytest.approx(1.25 / 7)
    with pytest.raises(ValueError):
        SyncModel(np.zeros(3), 1.0, np.ones((3, 3)), 0)


class _Hold:
    def reset(self, omega_init: float) -> None:
        pass

    def act(self, context: object) -> int:
        return HOLD_ACTION


def test_evaluate_reports_change_and_alteration() -> None:
    with_l2 = evaluate(_Hold(), TABLE2[1])
    assert set(with_l2) == {"r_without", "r_with", "change_pct", "alteration_mean", "alteration_max"}
    assert with_l2["change_pct"] == pytest.approx(100 * (with_l2["r_with"] / with_l2["r_without"] - 1))
    assert 0 < with_l2["alteration_mean"] <= with_l2["alteration_max"] <= np.pi / 2
    without = evaluate(_Hold(), TABLE2[1], l2=False)
    assert without["r_with"] == without["r_without"] and without["alteration_max"] == 0


class _Replay:
    """An L3 policy that plays one recorded action per tick and per run (``actions[k, b]``), batched or not."""

    def __init__(self, actions: np.ndarray, row: int | None = None) -> None:
        self.actions, self.row = actions, row

    def act(self, context) -> int:
        return int(self.actions[context.k, self.row])

    def act_rows(self, context) -> np.ndarray:
        return self.actions[context.k]


@pytest.mark.parametrize("group_number", [1, 3])
def test_the_numpy_twin_equals_the_batched_diagram(group_number: int) -> None:
    """SyncEnv (the vector environment's engine) is an independent reference of the closed-loop diagram."""
    from cogblocks.diagrams.sync import pop_sync
    from cogblocks.sim import Simulator
    from cogblocks.sync import OscillatorMotion
    from cogblocks.sync.blending import DELIVERABLE

    group = TABLE2[group_number]
    ticks, batch = 1000, 3
    rng = np.random.default_rng(11)
    actions = np.stack(
        [
            np.full(ticks, len(ACTIONS) - 1),
            rng.integers(len(ACTIONS), size=ticks),
            rng.integers(len(ACTIONS), size=ticks),
        ],
        axis=1,
    )
    env = run_env(SyncEnv.from_group(group, batch, blender=DELIVERABLE), actions)
    motion = OscillatorMotion(_Replay(actions), n=group.n, assisted=group.assisted, gain=group.gain,
                              omega_init=float(np.mean(group.omega)), adjacency=group.graph)  # fmt: skip
    diagram = pop_sync(group, motion=motion, blender="deliverable")
    trace = Simulator(diagram, probes={"theta": "group.theta", "lam": "l2.lam"}, batch=batch).run(n_steps=ticks)
    assert np.max(np.abs(wrap_pi(trace["theta"] - env["theta"][:ticks]))) <= 1e-12
    assert np.max(np.abs(trace["r"] - env["r"][:ticks])) <= 1e-12
    assert np.max(np.abs(trace["lam"] - env["lam"][:ticks])) <= 1e-12
