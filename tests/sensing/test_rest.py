"""The rest gate and the speed bound of a still hand's smoothed velocity estimate (cogblocks.sensing.rest)."""

import math
import re

import numpy as np
import pytest
import scipy.stats

from cogblocks.blocks import LowPass, Playback, Probe
from cogblocks.sensing import KalmanEstimator, RestGate, rest_cutoff, rest_speed_bound
from cogblocks.sim import Diagram, Signal, Simulator


def _still_hand(noise: float, cutoff: float | None, n: int, seed: int) -> np.ndarray:
    """The velocity estimate of a still marker at (100, -50, 20) mm seen with ``noise`` mm: the blocks themselves."""
    z = np.array([100.0, -50.0, 20.0]) + np.random.default_rng(seed).normal(scale=noise, size=(n, 3))
    d = Diagram()
    tracked = d.add("tracked", Playback(z, unit="mm", at_end="hold"))
    kalman = d.add("kalman", KalmanEstimator("ca", measurement_noise=noise, gate=None))
    d.connect(tracked.y, kalman.p)
    source = kalman.v_hat
    if cutoff is not None:
        smooth = d.add("smooth", LowPass(cutoff))
        d.connect(kalman.v_hat, smooth.u)
        source = smooth.y
    d.add("v", Probe())
    d.connect(source, "v.u")
    return Simulator(d).run(n_steps=n)["v"][300:]  # past the start-up transient


@pytest.mark.parametrize(("noise", "cutoff"), [(0.3, 3.0), (1.0, 5.0), (1.0, None)])
def test_the_bound_is_the_simulated_estimate_s_spread(noise, cutoff):
    # an independent computation: the blocks run on a still hand; the bound is from the Riccati equation
    v = _still_hand(noise, cutoff, 6000, seed=11)
    chi = math.sqrt(scipy.stats.chi2.ppf(0.9, 3))
    predicted = rest_speed_bound(noise, cutoff, quantile=0.9) / chi  # the error's deviation per axis
    assert v.std(axis=0) == pytest.approx(np.full(3, predicted), rel=0.12)
    # the speed exceeds the 0.9 bound about one time in ten (samples are correlated: a loose tolerance)
    exceeded = np.mean(np.linalg.norm(v, axis=1) > rest_speed_bound(noise, cutoff, quantile=0.9))
    assert 0.04 < exceeded < 0.2


def test_the_bound_scales_with_the_noise_and_falls_with_the_cut_off():
    # the filter fixed (measurement_noise given), the error is linear in the noise
    one = rest_speed_bound(1.0, 3.0, measurement_noise=0.5)
    assert rest_speed_bound(2.0, 3.0, measurement_noise=0.5) == pytest.approx(2.0 * one)
    assert rest_speed_bound(0.0, 3.0, measurement_noise=0.5) == 0.0
    bounds = [rest_speed_bound(0.3, cutoff) for cutoff in (2.0, 3.0, 5.0, 8.0)]
    assert bounds == sorted(bounds) and bounds[-1] < rest_speed_bound(0.3, None)
    assert rest_speed_bound(0.3, 3.0, quantile=0.99) < rest_speed_bound(0.3, 3.0, quantile=0.999)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"noise": -1.0, "cutoff": 3.0}, "noise must be a finite number in [0.0, inf), got -1.0"),
        ({"noise": 0.3, "cutoff": 50.0}, "cutoff must be a finite number in (0.0, 50.0), got 50.0"),
        ({"noise": 0.0, "cutoff": 3.0}, "measurement_noise must be a finite number in (0.0, inf), got 0.0"),
        ({"noise": 0.3, "cutoff": 3.0, "quantile": 1.0}, "quantile must be a finite number in (0.0, 1.0), got 1.0"),
        ({"noise": 0.3, "cutoff": 3.0, "model": "cj"}, "model must be one of"),
    ],
)
def test_the_bound_refuses_bad_arguments(kwargs, message):
    with pytest.raises(ValueError, match=re.escape(f"rest_speed_bound: {message}")):
        rest_speed_bound(**kwargs)


def _gate(threshold: float, samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    d = Diagram()
    source = d.add("source", Playback(samples, unit="mm/s"))
    gate = d.add("gate", RestGate(threshold))
    d.connect(source.y, gate.u)
    for name in ("y", "rest"):
        d.add(name, Probe())
        d.connect(f"gate.{name}", f"{name}.u")
    trace = Simulator(d).run(n_steps=len(samples))
    return trace["y"], trace["rest"]


def test_the_gate_zeroes_a_speed_at_or_below_its_threshold_and_passes_the_rest():
    samples = np.array([[3.0, 4.0, 0.0], [3.0, 4.0, 0.1], [0.0, 0.0, -5.0], [1e-3, 0.0, 0.0], [30.0, -40.0, 0.0]])
    y, rest = _gate(5.0, samples)
    assert rest.tolist() == [True, False, True, True, False]
    np.testing.assert_array_equal(y, np.where(rest[:, None], 0.0, samples))
    y, rest = _gate(0.0, samples)  # a zero threshold passes every nonzero sample unchanged
    np.testing.assert_array_equal(y, samples)
    assert not rest.any()


def test_the_gate_passes_a_non_finite_sample():
    d = Diagram()
    gate = d.add("gate", RestGate(5.0))
    d.expose_input("u", gate.u, spec=Signal(shape=(3,), unit="mm/s"))
    d.expose_output("y", gate.y)
    d.expose_output("rest", gate.rest)
    compiled = d.compile()
    out = compiled.step(u=np.array([np.nan, 0.0, 0.0]))
    assert np.isnan(out["y"][0]) and not out["rest"]


def test_the_cut_off_is_the_least_smoothing_within_the_bound():
    cutoff = rest_cutoff(1.0, 12.0, highest=3.0)
    assert 0.1 < cutoff < 3.0
    assert rest_speed_bound(1.0, cutoff) == pytest.approx(12.0, rel=1e-4)
    assert rest_speed_bound(1.0, cutoff * 1.05) > 12.0  # any less smoothing shows more than the bound
    # clipped: no noise (or little) needs no more smoothing than the highest cut-off, much noise the lowest
    assert rest_cutoff(0.0, 12.0, highest=3.0, measurement_noise=0.1) == 3.0
    assert rest_cutoff(0.3, 12.0, highest=3.0) == 3.0
    assert rest_cutoff(100.0, 12.0, highest=3.0, lowest=0.5) == 0.5
    # more noise, more smoothing
    assert rest_cutoff(2.0, 12.0, highest=3.0) < cutoff


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"bound": 0.0, "highest": 3.0}, "bound must be a finite number in (0.0, inf), got 0.0"),
        ({"bound": 12.0, "highest": 60.0}, "highest must be a finite number in (0.0, 50.0), got 60.0"),
        ({"bound": 12.0, "highest": 3.0, "lowest": 4.0}, "lowest must be a finite number in (0.0, 3.0], got 4.0"),
    ],
)
def test_the_cut_off_refuses_bad_arguments(kwargs, message):
    with pytest.raises(ValueError, match=re.escape(f"rest_cutoff: {message}")):
        rest_cutoff(1.0, **kwargs)
