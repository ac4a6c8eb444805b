"""The simulated sensor of cogblocks.data.sensor: seeded, and every fault where its masks say."""

import numpy as np
import pytest

from cogblocks.data.sensor import simulate_sensor


def test_seeded_and_reproducible():
    a = simulate_sensor(10.0, rate_hz=40.0, seed=3, quantisation=0.05)
    b = simulate_sensor(10.0, rate_hz=40.0, seed=3, quantisation=0.05)
    c = simulate_sensor(10.0, rate_hz=40.0, seed=4, quantisation=0.05)
    np.testing.assert_array_equal(a.value, b.value)
    np.testing.assert_array_equal(a.phase, b.phase)
    assert not np.array_equal(np.nan_to_num(a.value), np.nan_to_num(c.value))


@pytest.mark.parametrize("rate", [25.0, 240.0])
def test_rate_and_jitter(rate):
    rec = simulate_sensor(20.0, rate_hz=rate, seed=1, jitter=0.2)
    k = np.arange(len(rec.t))
    assert len(rec.t) == round(20.0 * rate) and rec.dt == 1.0 / rate
    offset = rec.t - k / rate
    assert np.abs(offset).max() <= 0.45 / rate + 1e-12 and np.std(offset[1:]) > 0.1 / rate
    exact = simulate_sensor(20.0, rate_hz=rate, seed=1, jitter=0.0)
    np.testing.assert_allclose(exact.t, k / rate, atol=1e-12)


def test_true_phase_is_the_phase_of_the_movement():
    rec = simulate_sensor(
        30.0,
        rate_hz=100.0,
        seed=2,
        harmonics=0.0,
        amplitude_drift=0.0,
        noise=0.0,
        spike_rate=0.0,
        dropout_rate=0.0,
        jitter=0.0,
    )
    # without harmonics and amplitude drift, clean = centre(t) + A cos(phase): the true phase is the shift of
    # cos(phase + s) that matches the (slowly re-centred) position best, to the resolution of the scan
    centred = rec.clean - np.convolve(rec.clean, np.ones(101) / 101, "same")
    shifts = np.linspace(-0.3, 0.3, 25)
    fit = [np.corrcoef(centred[200:-200], np.cos(rec.phase + s)[200:-200])[0, 1] for s in shifts]
    assert abs(shifts[int(np.argmax(fit))]) < 0.03
    assert max(fit) > 0.97
    assert np.all((rec.phase >= 0.0) & (rec.phase < 2 * np.pi))
    assert 0.4 * 0.9 - 1e-9 <= rec.frequency.min() and rec.frequency.max() <= 1.2 * 1.1 + 1e-9  # range, ±10 % wobble


def test_quantisation_makes_samples_repeat_on_the_grid():
    rec = simulate_sensor(30.0, rate_hz=240.0, seed=5, quantisation=0.05, spike_rate=0.0, dropout_rate=0.0)
    assert rec.step > 0.0
    np.testing.assert_allclose(rec.value / rec.step, np.round(rec.value / rec.step), atol=1e-6)
    assert np.mean(np.diff(rec.value) == 0.0) > 0.3  # at 240 Hz a 5 % step holds for several samples


def test_scale_is_the_unit():
    small = simulate_sensor(20.0, seed=7, scale=0.01)
    large = simulate_sensor(20.0, seed=7, scale=1000.0)
    np.testing.assert_allclose(large.clean, small.clean * 1e5, rtol=1e-9)
    np.testing.assert_array_equal(small.phase, large.phase)
    assert 0.5 * 0.01 * 0.4 < small.amplitude.mean() < 2.0 * 0.01 * 2.5


def test_masks_say_where_the_faults_are():
    rec = simulate_sensor(60.0, rate_hz=60.0, seed=11, dropout_rate=10.0, spike_rate=10.0, quantisation=0.0)
    assert rec.missing.any() and rec.frozen.any() and rec.spike.any()
    np.testing.assert_array_equal(np.isnan(rec.value), rec.missing)
    frozen = np.flatnonzero(rec.frozen)
    assert np.all(rec.value[frozen] == rec.value[frozen - 1])
    good = ~rec.bad
    base = np.std(rec.value[good] - rec.clean[good])
    assert np.all(np.abs(rec.value[rec.spike] - rec.clean[rec.spike]) > 3.0 * np.median(rec.amplitude))
    assert base < 0.01 * np.median(rec.amplitude)


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"rate_hz": 0.0}, r"simulate_sensor: rate_hz must be a finite number in \(0.0, inf\), got 0.0"),
        ({"scale": -1.0}, r"simulate_sensor: scale must be a finite number in \(0.0, inf\), got -1.0"),
        ({"jitter": 0.5}, r"simulate_sensor: jitter must be a finite number in \[0.0, 0.3\], got 0.5"),
        ({"duration": 0.1}, r"simulate_sensor: duration must hold at least 16 samples at 100.0 Hz, got 0.1"),
        ({"freq_range": (1.0, 40.0)}, r"simulate_sensor: freq_range must be a pair \(lo, hi\)"),
    ],
)
def test_parameter_errors(params, message):
    with pytest.raises(ValueError, match=message):
        simulate_sensor(**{"duration": 10.0, **params})
