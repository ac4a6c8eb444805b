"""Naturalness metrics against hand-built signals with known jumps, speeds and jerks, and in the ready diagrams."""

import numpy as np
import pytest

from cogblocks.diagrams.naturalness import (
    alteration_steps,
    movement_naturalness,
    naturalness_text,
    phase_naturalness,
    phase_speed,
    position_naturalness,
)
from cogblocks.diagrams.sync import pop_sync, simulate, sync_table

DT = 0.01


def _person(seconds: float = 60.0, speed: float = 2.0) -> np.ndarray:
    return speed * DT * np.arange(round(seconds / DT) + 1)


def test_an_avatar_that_is_the_person_has_no_jump_and_the_same_speed():
    theta = _person()
    assert phase_naturalness(theta, theta) == {"max_step_rad": 0.0, "jumps_per_min": 0.0, "peak_speed_ratio": 1.0}
    assert position_naturalness(np.cos(theta), np.cos(theta)) == {
        "position_peak_speed_ratio": 1.0,
        "position_rms_jerk_ratio": 1.0,
    }


def test_a_sign_flip_of_the_alteration_is_one_jump_of_twice_lambda():
    theta_l0 = _person(seconds=60.0)  # 6000 ticks: one minute of steps
    alteration = np.where(np.arange(theta_l0.size) < 3000, 0.3, -0.3)
    alteration[4000:] = -0.3 + 0.001 * np.arange(theta_l0.size - 4000)  # a slow drift: 1 mrad per tick, no jump
    figures = phase_naturalness(np.mod(theta_l0 + alteration, 2 * np.pi), np.mod(theta_l0, 2 * np.pi))
    assert figures["max_step_rad"] == pytest.approx(0.6)
    assert figures["jumps_per_min"] == pytest.approx(1.0)
    # the person runs at 2 rad/s; the avatar's fastest tick moves 0.02 − 0.6 rad: 58 rad/s
    assert figures["peak_speed_ratio"] == pytest.approx(58.0 / 2.0)


def test_an_alteration_crossing_pi_is_a_small_change():
    alteration = np.linspace(3.0, 3.3, 31)  # passes π: wrapped it jumps from +π to −π
    steps = alteration_steps(alteration, np.zeros_like(alteration))
    assert steps.max() == pytest.approx(0.01)
    assert phase_speed(np.mod(_person(1.0, speed=5.0), 2 * np.pi)) == pytest.approx(np.full(100, 5.0))


def test_jumps_count_only_above_the_threshold():
    theta_l0 = _person(seconds=30.0)  # 3000 steps: half a minute
    alteration = np.zeros_like(theta_l0)
    alteration[100:] += 0.04  # below 0.05: not a jump
    alteration[200:] += 0.06
    alteration[300:] -= 0.5
    figures = phase_naturalness(theta_l0 + alteration, theta_l0)
    assert figures["jumps_per_min"] == pytest.approx(2 / 0.5)
    assert figures["max_step_rad"] == pytest.approx(0.5)


def test_position_ratios_scale_with_the_amplitude():
    t = DT * np.arange(500)
    person = np.stack([np.sin(3 * t), np.cos(2 * t)], axis=1)
    figures = position_naturalness(2.5 * person, person)
    assert figures["position_peak_speed_ratio"] == pytest.approx(2.5)
    assert figures["position_rms_jerk_ratio"] == pytest.approx(2.5)
    # a 100 mm teleport in one tick: the peak speed is 100 mm / 10 ms against the person's 150 mm · 3 rad/s
    arm = 150.0 * np.sin(3 * t)
    teleport = arm + np.where(t >= 2.0, 100.0, 0.0)
    speed = position_naturalness(teleport, arm)["position_peak_speed_ratio"]
    expected = np.abs(np.diff(teleport)).max() / np.abs(np.diff(arm)).max()
    assert speed == pytest.approx(expected) and speed > 20


def test_movement_figures_per_movement():
    t = DT * np.arange(200)[:, None]
    human = [np.hstack([np.sin(2 * t), np.cos(3 * t), 0 * t]) * k for k in (100.0, 200.0)]
    same = movement_naturalness(human, human)
    assert same["velocity_step_ratio"] == {"median": 1.0, "max": 1.0}
    assert same["rms_jerk_ratio"]["max"] == pytest.approx(1.0) and same["steps_within_share"] == 1.0
    kicked = [human[0].copy(), 2.0 * human[1]]
    kicked[0][120:, 2] += 50.0  # a 50 mm/s step in one tick on the z axis
    figures = movement_naturalness(kicked, human)
    step0 = (
        np.linalg.norm(np.diff(kicked[0], axis=0), axis=1).max()
        / np.linalg.norm(np.diff(human[0], axis=0), axis=1).max()
    )
    assert figures["velocity_step_ratio"]["max"] == pytest.approx(step0)
    assert figures["velocity_step_ratio"]["median"] == pytest.approx((step0 + 2.0) / 2)
    assert figures["peak_accel_ratio"] == figures["velocity_step_ratio"]
    assert figures["steps_within_share"] == 0.0


def test_bad_traces_are_refused_by_name():
    with pytest.raises(ValueError, match="theta_l2 .* differ in length"):
        phase_naturalness(np.zeros(10), np.zeros(11))
    with pytest.raises(ValueError, match="theta_l0 must be a finite 1D trace"):
        phase_naturalness(np.zeros(10), np.full(10, np.nan))
    with pytest.raises(ValueError, match="p_person must be a finite"):
        position_naturalness(np.zeros(10), np.zeros(3))
    with pytest.raises(ValueError, match="as many altered as human"):
        movement_naturalness([np.zeros((10, 3))], [])


@pytest.mark.parametrize("domain", ["phase", "position"])
def test_sync_table_rows_measure_the_probed_run(domain):
    head, row = sync_table(1, ["mean"], domain, duration=3.0)
    probes = {"theta_l2": "l2.theta_l2", "theta_l0": "l2.theta_l0", "theta": "group.theta"}
    trace = simulate(pop_sync(1, motion="mean", domain=domain), 301, probes, label="test")
    change = np.angle(np.exp(1j * np.diff(trace["theta_l2"] - trace["theta_l0"])))
    assert row["max_step_rad"] == pytest.approx(np.abs(change).max())
    assert row["jumps_per_min"] == pytest.approx(np.sum(np.abs(change) > 0.05) / (3.0 / 60))
    assert ("position_rms_jerk_ratio" in row) == (domain == "position")
    assert "largest step" in naturalness_text(row)
