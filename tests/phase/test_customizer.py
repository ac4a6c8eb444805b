"""The reference customizer's default (a least-squares linear map) against the deliverable's scale-then-rotate."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cogblocks.data.motion3d import reference_primitive
from cogblocks.phase import ReferenceCustomizer, customize_reference

TWO_PI = 2 * np.pi


def figure(phase):
    """An asymmetric closed curve, with spreads that differ along every axis."""
    return np.stack([120 * np.cos(phase), 60 * np.sin(phase) + 20 * np.cos(2 * phase), 35 * np.sin(2 * phase)], -1)


@pytest.mark.parametrize("degrees", [0.0, 45.0, 90.0, 135.0, 180.0])
def test_any_rotation_and_scale_is_recovered_exactly(degrees):
    n, m = 500, 173  # a period that is no divisor of the reference
    reference = figure(TWO_PI * np.arange(n) / n)
    rotation = Rotation.from_rotvec(np.radians(degrees) * np.array([1.0, 2.0, 0.5]) / np.sqrt(5.25)).as_matrix()
    scale = np.array([1.4, 0.6, 0.9])  # along the reference's own axes, then rotated: the person's build
    curve = figure(TWO_PI * np.arange(m) / m)
    period = ((curve - curve.mean(axis=0)) * scale) @ rotation.T + [300.0, -50.0, 900.0]
    positions, _ = customize_reference(reference, period, dt=0.01)
    # linear resampling of a 500-sample curve of radius ~120 mm is off by ~2e-3 mm; a linear map adds nothing
    np.testing.assert_allclose(positions, period, atol=0.02)
    deliverable, _ = customize_reference(reference, period, dt=0.01, customization="deliverable")
    error = np.abs(deliverable - period).max()
    if degrees in (0.0, 180.0) and np.allclose(np.abs(rotation), np.eye(3)):
        assert error < 0.02  # world axes and reference axes coincide
    elif degrees >= 45.0:
        assert error > 5.0  # the spreads were compared along the wrong axes


def test_the_deliverable_variant_is_the_old_per_axis_scaling():
    reference = reference_primitive(200)
    period = reference_primitive(150) * [0.8, 1.5, 1.1] + [10.0, 20.0, -30.0]
    for customization in ("affine", "deliverable"):
        positions, _ = customize_reference(reference, period, customization=customization)
        np.testing.assert_allclose(positions, period, atol=0.2)


def test_customization_is_checked():
    with pytest.raises(ValueError, match=r"customization must be one of"):
        customize_reference(reference_primitive(20), reference_primitive(20), customization="similar")
    with pytest.raises(ValueError, match=r"ReferenceCustomizer: customization must be one of"):
        ReferenceCustomizer(reference_primitive(20), customization="rigid")


def test_generator_speed_wobble_makes_the_speed_uneven_within_a_cycle():
    from cogblocks.data.motion3d import generate_motion3d

    plain = generate_motion3d(2, duration=20.0)
    same = generate_motion3d(2, duration=20.0, speed_wobble=0.0)
    np.testing.assert_array_equal(plain.position, same.position)  # the default keeps the random stream
    uneven = generate_motion3d(2, duration=20.0, speed_wobble=0.3, period_drift=0.0, dropout_rate=0.0)
    steady = generate_motion3d(2, duration=20.0, period_drift=0.0, dropout_rate=0.0)
    speed = np.diff(np.unwrap(uneven.phase))
    # fastest over slowest phase speed is (1 + 0.3) / (1 - 0.3) = 1.86; without the wobble it is ~1
    assert speed.max() / speed.min() == pytest.approx(1.3 / 0.7, rel=0.05)
    steady_speed = np.diff(np.unwrap(steady.phase))
    assert steady_speed.max() / steady_speed.min() < 1.05


def wobbly_period(m=181, wobble=0.25):
    """One cycle of ``figure`` rotated by 150° and scaled, sampled evenly in time with the speed ±25 % in phase."""
    from scipy.integrate import cumulative_trapezoid

    grid = np.linspace(0.0, TWO_PI, 4001)
    time = cumulative_trapezoid(1.0 / (1.0 + wobble * np.cos(grid + 1.0)), grid, initial=0.0)
    phases = np.interp(np.arange(m) * time[-1] / m, time, grid)  # true phase of each sample
    rotation = Rotation.from_rotvec(np.radians(150.0) * np.array([0.3, -0.5, 0.81]) / 1.0).as_matrix()
    transform = np.diag([1.2, 0.7, 1.1]) @ rotation.T
    return phases, figure(phases) @ transform + [50.0, 400.0, 900.0], transform


def test_anchored_reference_needs_no_even_speed():
    from cogblocks.phase.customizer import anchored_reference

    reference = figure(TWO_PI * np.arange(400) / 400)
    phases, period, transform = wobbly_period()
    even = TWO_PI * np.arange(len(period)) / len(period)  # the first period's phases: even in time
    assert np.abs(even - phases).max() > 0.2
    a_t, c = anchored_reference(reference, period, even, anchor="start", iterations=32)
    # the nearest points re-estimate the phases (each pass removes ~15 % of the error): the fitted curve
    # is the true one, phase for phase
    grid = TWO_PI * np.arange(90) / 90
    truth = figure(grid) @ transform + [50.0, 400.0, 900.0]
    np.testing.assert_allclose(figure(grid) @ a_t + c, truth, atol=0.5)
    a_once, c_once = anchored_reference(reference, period, even, anchor="start", iterations=0)
    assert np.abs(figure(grid) @ a_once + c_once - truth).max() > 5.0  # the fit by sample count alone is off


def test_anchored_reference_keeps_the_given_phase_origin_on_average():
    from cogblocks.phase.customizer import anchored_reference

    reference = figure(TWO_PI * np.arange(400) / 400)
    phases, period, _ = wobbly_period()
    a_t, c = anchored_reference(reference, period, phases + 0.05, anchor="mean")
    # the phases were 0.05 rad ahead of the truth: on the fitted curve the samples still are, on average,
    # up to the part of a phase shift no linear map can mimic (here about a fifth of it): an error of the
    # given phases is kept or reduced, never amplified
    fine = TWO_PI * np.arange(20000) / 20000
    curve = figure(fine) @ a_t + c
    nearest = fine[np.argmin(((period[:, None, :] - curve[None, :, :]) ** 2).sum(axis=2), axis=1)]
    assert 0.03 < np.mean(np.angle(np.exp(1j * (nearest - phases)))) <= 0.05
    with pytest.raises(ValueError, match=r"anchored_reference: phases must have shape \(181\), got \(180,\)"):
        anchored_reference(reference, period, phases[:-1])
