"""KalmanEstimator and fit_noise on synthetic motion-capture streams."""

from __future__ import annotations

import math

import numpy as np
import pytest
from filterpy.common import Q_continuous_white_noise

from cogblocks.blocks import Playback
from cogblocks.sensing import KalmanEstimator, fit_noise
from cogblocks.sim import Diagram, DiagramError, Simulator

DT = 0.01
OUTPUTS = ("p_hat", "v_hat", "a_hat", "predicted")


def estimate(data: np.ndarray, *, period: float | None = None, **options) -> dict[str, np.ndarray]:
    """Run a KalmanEstimator over ``data`` (one row per base tick); return its outputs by name."""
    d = Diagram()
    d.add("src", Playback(data, unit="mm"))
    d.add("est", KalmanEstimator(period=period, **options))
    d.connect("src.y", "est.p")
    trace = Simulator(d, DT, probes={name: f"est.{name}" for name in OUTPUTS}).run(n_steps=len(data))
    return {name: trace[name] for name in OUTPUTS}


def sinusoid(n: int, amplitude: float = 150.0, freq: float = 0.75) -> tuple[np.ndarray, np.ndarray]:
    """Position and velocity of a sinusoid sampled every DT."""
    w = 2 * np.pi * freq
    t = np.arange(n) * DT
    return amplitude * np.sin(w * t), amplitude * w * np.cos(w * t)


def noisy_sinusoid(n: int, seed: int, sigma: float = 2.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    p, v = sinusoid(n)
    return p + sigma * np.random.default_rng(seed).standard_normal(n), p, v


def rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


# -- the filterpy pieces the estimator relies on (filterpy >= 1.4.5, 2.x included) -------------------


def test_filterpy_noise_matrix_and_step_follow_the_textbook_equations():
    """Q of a white-noise (jerk or acceleration) model, and one predict + update, written out by hand."""
    from filterpy.kalman import KalmanFilter

    dt, q, n = 0.02, 3.0, 2
    cv = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    ca = q * np.array(
        [[dt**5 / 20, dt**4 / 8, dt**3 / 6], [dt**4 / 8, dt**3 / 3, dt**2 / 2], [dt**3 / 6, dt**2 / 2, dt]]
    )
    np.testing.assert_allclose(Q_continuous_white_noise(2, dt, q), cv, rtol=1e-12)
    np.testing.assert_allclose(Q_continuous_white_noise(3, dt, q), ca, rtol=1e-12)
    # state ordered by axis (p0, v0, p1, v1), as the estimator's H = kron(I, e_0) assumes
    Q = Q_continuous_white_noise(2, dt, q, block_size=n)
    np.testing.assert_allclose(Q, np.kron(np.eye(n), cv), rtol=1e-12)

    F = np.kron(np.eye(n), np.array([[1.0, dt], [0.0, 1.0]]))
    H = np.kron(np.eye(n), np.eye(1, 2))
    R = 4.0 * np.eye(n)
    x, P, z = np.array([1.0, 2.0, -1.0, 0.5]), np.diag([5.0, 1.0, 3.0, 2.0]), np.array([1.3, -0.8])
    kf = KalmanFilter(dim_x=2 * n, dim_z=n)
    kf.F, kf.Q, kf.H, kf.R, kf.x, kf.P = F, Q, H, R, x.copy(), P.copy()
    kf.predict()
    kf.update(z)
    x_prior, P_prior = F @ x, F @ P @ F.T + Q
    gain = P_prior @ H.T @ np.linalg.inv(H @ P_prior @ H.T + R)
    np.testing.assert_allclose(kf.x, x_prior + gain @ (z - H @ x_prior), rtol=1e-12)
    np.testing.assert_allclose(kf.P, (np.eye(2 * n) - gain @ H) @ P_prior, rtol=1e-9, atol=1e-12)


# -- clean and noisy motion ------------------------------------------------------


@pytest.mark.parametrize("model", ["cv", "ca"])
def test_clean_ramp_gives_the_exact_velocity_after_convergence(model):
    t = np.arange(300) * DT
    velocity = np.array([100.0, -40.0, 7.5])
    ramp = np.array([5.0, 20.0, -3.0]) + t[:, None] * velocity
    out = estimate(ramp, model=model)
    # the filter tracks a ramp with no steady-state error; 1 s is many time constants at 2 mm noise
    np.testing.assert_allclose(out["v_hat"][100:], np.broadcast_to(velocity, (200, 3)), rtol=0, atol=1e-8)
    np.testing.assert_allclose(out["p_hat"][100:], ramp[100:], rtol=0, atol=1e-9)
    np.testing.assert_allclose(out["a_hat"][100:], 0.0, atol=1e-6)
    assert not out["predicted"].any()


@pytest.mark.parametrize("model", ["cv", "ca"])
def test_noisy_sinusoid_velocity_beats_finite_differences(model):
    z, _, v = noisy_sinusoid(1500, seed=1)
    out = estimate(z, model=model)
    settled = slice(100, None)
    kalman = rms(out["v_hat"][settled] - v[settled])
    # independent baselines: the causal backward difference (the same information as the filter) and
    # the non-causal central difference, whose noise is sqrt(2) sigma / (2 dt) = 141 mm/s at 2 mm
    backward = np.full_like(z, np.nan)
    backward[1:] = (z[1:] - z[:-1]) / DT
    central = np.full_like(z, np.nan)
    central[1:-1] = (z[2:] - z[:-2]) / (2 * DT)
    assert kalman < 0.5 * rms(backward[settled] - v[settled])
    assert kalman < rms(central[settled][:-1] - v[settled][:-1])


# -- bad data --------------------------------------------------------------------


def test_no_output_before_the_first_sample():
    z = np.r_[np.full(3, np.nan), np.arange(10.0)]
    out = estimate(z, model="cv")
    assert np.isnan(out["p_hat"][:3]).all() and out["predicted"][:3].all()
    assert out["p_hat"][3] == 0.0 and not out["predicted"][3]


@pytest.mark.parametrize("model", ["cv", "ca"])
def test_nan_frames_are_predicted_along_the_model(model):
    z, p, _ = noisy_sinusoid(400, seed=2)
    gaps = [150, 151, 152, 153, 154, 250, 300]
    z[gaps] = np.nan
    out = estimate(z, model=model)
    assert np.isfinite(out["p_hat"]).all() and np.isfinite(out["v_hat"]).all()
    assert out["predicted"][gaps].all()
    assert out["predicted"].sum() <= len(gaps) + 1  # at most one false rejection by the 99.9 % gate
    for k in gaps:
        p0, v0, a0 = out["p_hat"][k - 1], out["v_hat"][k - 1], out["a_hat"][k - 1]
        np.testing.assert_allclose(out["p_hat"][k], p0 + v0 * DT + 0.5 * a0 * DT**2, rtol=1e-12)
        np.testing.assert_allclose(out["v_hat"][k], v0 + a0 * DT, rtol=1e-12)
    # after a 50 ms gap the error is about that of the estimate, 3 sigma_p ~ 4 mm, plus 50 ms of its velocity
    # error, 0.05 * 3 sigma_v ~ 15 mm/s (cv) or 8 mm/s (ca); cv also misses the curvature, ½ A ω² τ² ≈ 4 mm
    assert np.abs(out["p_hat"][gaps] - p[gaps]).max() < 12.0


def test_a_3d_sample_with_one_nan_component_is_missing_as_a_whole():
    t = np.arange(200) * DT
    z = np.stack([100 * t, 50 * t, -20 * t], axis=1)
    z[120, 1] = np.nan
    out = estimate(z, model="cv")
    assert out["predicted"][120] and np.isfinite(out["p_hat"][120]).all()
    np.testing.assert_allclose(out["p_hat"][120], [120.0, 60.0, -24.0], atol=1e-6)


def test_spikes_are_rejected():
    z, p, _ = noisy_sinusoid(600, seed=3)
    spikes = {200: 60.0, 320: -80.0, 321: 90.0, 450: 50.0}
    for k, size in spikes.items():
        z[k] += size
    out = estimate(z, model="ca")
    ks = list(spikes)
    assert out["predicted"][ks].all()
    assert np.abs(out["p_hat"][ks] - p[ks]).max() < 5.0
    assert np.abs(out["p_hat"][100:] - p[100:]).max() < 8.0


@pytest.mark.parametrize("max_rejections", [1, 2, 5])
def test_a_real_step_is_accepted_after_max_rejections(max_rejections):
    n, step_at = 400, 200
    z = 2.0 * np.random.default_rng(4).standard_normal(n)
    z[step_at:] += 100.0
    out = estimate(z, model="cv", max_rejections=max_rejections)
    rejected = step_at + max_rejections - 1  # the frame of the re-initialisation
    assert out["predicted"][step_at:rejected].all()
    assert not out["predicted"][rejected]
    # the replay of the rejected samples puts the estimate on the new level at once
    assert abs(out["p_hat"][rejected] - 100.0) < 10.0
    assert np.abs(out["p_hat"][rejected + 50 :] - 100.0).max() < 8.0  # 5 times the 1.5 mm filtered noise
    assert out["predicted"][rejected + 1 :].sum() <= 1


def test_without_the_gate_every_finite_sample_is_used():
    z, _, _ = noisy_sinusoid(300, seed=5)
    z[150] += 500.0
    out = estimate(z, model="cv", gate=None)
    assert not out["predicted"].any()
    assert out["p_hat"][150] > 100.0  # the spike pulls the estimate


@pytest.mark.parametrize("freeze_frames", [2, 4])
def test_frozen_values_are_missing_after_freeze_frames_repeats(freeze_frames):
    z, p, _ = noisy_sinusoid(400, seed=6)
    start = 200  # z[start - 1] repeated over 20 frames through a zero crossing, with a dropout inside the run
    z[start : start + 20] = z[start - 1]
    z[start + 10] = np.nan
    out = estimate(z, model="cv", freeze_frames=freeze_frames)
    first_missing = start - 1 + freeze_frames
    assert not out["predicted"][start:first_missing].any()
    assert out["predicted"][first_missing : start + 20].all()
    # once confirmed, the filter rewinds: the whole run counts as missing, as with freeze_frames=1
    reference = estimate(z, model="cv", freeze_frames=1)
    assert reference["predicted"][start : start + 20].all()
    for name in OUTPUTS:
        np.testing.assert_array_equal(out[name][first_missing:], reference[name][first_missing:])
    # a 200 ms prediction misses by about 0.2 s times the velocity error (sigma_v ~ 100 mm/s for cv at 2 mm)
    assert np.abs(reference["p_hat"][start : start + 20] - p[start : start + 20]).max() < 25.0
    assert np.abs(out["p_hat"][start + 30 :] - p[start + 30 :]).max() < 8.0


def test_freeze_detection_can_be_turned_off():
    z = np.r_[np.arange(100.0), np.full(20, 99.0), 99.0 + np.arange(1, 81)]
    assert not estimate(z, model="cv", freeze_frames=None, gate=None)["predicted"].any()
    assert estimate(z, model="cv", gate=None)["predicted"][101:120].all()


# -- ports, rates and state ------------------------------------------------------


def test_port_specs_follow_the_input():
    d = Diagram()
    d.add("src", Playback(np.zeros((5, 3)), unit="m"))
    est = d.add("est", KalmanEstimator("ca", unit="m"))
    d.connect("src.y", "est.p")
    d.compile(DT)
    assert est.n == 3 and est.p_hat.spec.shape == (3,)
    assert (est.p_hat.spec.unit, est.v_hat.spec.unit, est.a_hat.spec.unit) == ("m", "m/s", "m/s^2")
    assert est.predicted.spec.dtype == np.dtype(bool) and est.predicted.spec.shape == ()
    assert est.gate_threshold == pytest.approx(16.266, abs=1e-3)  # chi-square 99.9 % quantile, 3 dof


def test_declared_dims_are_checked_when_connecting():
    d = Diagram()
    d.add("src", Playback(np.zeros(5), unit="mm"))
    d.add("est", KalmanEstimator(dims=3))
    with pytest.raises(DiagramError, match=r"shape \(\) != \(3,\)"):
        d.connect("src.y", "est.p")


def test_matrix_input_is_refused():
    d = Diagram()
    d.add("src", Playback(np.zeros((5, 3, 3)), unit="mm"))
    d.add("est", KalmanEstimator())
    d.connect("src.y", "est.p")
    with pytest.raises(DiagramError, match=r"est: p must be a scalar or a vector of positions, got shape \(3, 3\)"):
        d.compile(DT)


def test_slower_period_uses_its_own_step():
    ramp = 3.0 + 80.0 * np.arange(400) * DT
    out = estimate(ramp, model="cv", period=0.04)
    np.testing.assert_allclose(out["v_hat"][200:], 80.0, atol=1e-8)


def test_state_dict_round_trip_continues_identically():
    z, _, _ = noisy_sinusoid(500, seed=7)
    z[[120, 130, 131]] = np.nan
    z[140:150] = z[139]
    z[160] += 90.0
    z[197:] += 150.0  # the snapshot at tick 200 falls inside a rejection streak
    d = Diagram()
    d.add("src", Playback(z, unit="mm"))
    d.add("est", KalmanEstimator("ca"))
    d.connect("src.y", "est.p")
    sim = Simulator(d, DT, probes={name: f"est.{name}" for name in OUTPUTS})
    first = sim.run(n_steps=200)
    snapshot = sim.state_dict()
    assert snapshot["blocks"]["est"]["state"]["rejections"] == 3
    continued = sim.run(n_steps=300)
    sim.load_state_dict(snapshot)
    replayed = sim.run(n_steps=300)
    for name in OUTPUTS:
        np.testing.assert_array_equal(replayed[name], continued[name])
    sim.reset()
    again = sim.run(n_steps=200)
    for name in OUTPUTS:
        np.testing.assert_array_equal(again[name], first[name])


# -- parameters ------------------------------------------------------------------


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"model": "kalman"}, r"KalmanEstimator: model must be one of \['cv', 'ca'\], got 'kalman'"),
        ({"process_noise": -1.0}, r"KalmanEstimator: process_noise must be a finite number in \(0.0, inf\), got -1.0"),
        ({"measurement_noise": 0}, r"KalmanEstimator: measurement_noise must be .*, got 0"),
        ({"measurement_noise": float("nan")}, r"measurement_noise must be a finite number .*, got nan"),
        ({"gate": 1.0}, r"KalmanEstimator: gate must be a finite number in \(0.0, 1.0\), got 1.0"),
        ({"max_rejections": 0}, r"KalmanEstimator: max_rejections must be an integer >= 1, got 0"),
        ({"freeze_frames": 1.5}, r"KalmanEstimator: freeze_frames must be an integer >= 1, got 1.5"),
        ({"dims": 0}, r"KalmanEstimator: dims must be an integer >= 1, got 0"),
        ({"unit": ""}, r"KalmanEstimator: unit must be a non-empty string, got ''"),
    ],
)
def test_bad_parameters_are_named(options, message):
    with pytest.raises(ValueError, match=message):
        KalmanEstimator(**options)


# -- fit_noise -------------------------------------------------------------------


def simulate_model(model: str, q: float, sigma: float, n: int, seed: int) -> np.ndarray:
    """Exact samples of the continuous white-noise model every DT, plus white measurement noise."""
    order = {"cv": 2, "ca": 3}[model]
    f = np.array(
        [[DT ** (j - i) / math.factorial(j - i) if j >= i else 0.0 for j in range(order)] for i in range(order)]
    )
    chol = np.linalg.cholesky(Q_continuous_white_noise(order, DT, q))
    rng = np.random.default_rng(seed)
    w = rng.standard_normal((n, order)) @ chol.T
    x = np.zeros(order)
    out = np.empty(n)
    for k in range(n):
        out[k] = x[0]
        x = f @ x + w[k]
    return out + sigma * rng.standard_normal(n)


# Over 100 seeds of 20 000 samples the estimates had a relative spread of 5 % (q) and 0.7 % (sigma) with
# no visible bias, so a factor 1.25 on q and 5 % on sigma are beyond 5 standard deviations.
@pytest.mark.parametrize(("model", "q"), [("cv", 1e5), ("ca", 1e7)])
@pytest.mark.parametrize("robust", [True, False])
def test_fit_noise_recovers_known_noise(model, q, robust):
    fit = fit_noise(simulate_model(model, q, 2.0, 20_000, seed=8), DT, model, robust=robust)
    assert fit["model"] == model
    assert 1 / 1.25 < fit["process_noise"] / q < 1.25
    assert fit["measurement_noise"] == pytest.approx(2.0, rel=0.05)


def test_robust_fit_noise_ignores_spikes_and_dropouts():
    p = simulate_model("cv", 1e5, 2.0, 20_000, seed=9)
    rng = np.random.default_rng(10)
    p[rng.choice(len(p), 40, replace=False)] += rng.choice([-1.0, 1.0], 40) * 80.0
    p[rng.random(len(p)) < 0.02] = np.nan
    fit = fit_noise(p[:, None], DT, "cv")
    assert 1 / 1.25 < fit["process_noise"] / 1e5 < 1.25
    assert fit["measurement_noise"] == pytest.approx(2.0, rel=0.1)
    plain = fit_noise(p, DT, "cv", robust=False)
    assert plain["measurement_noise"] > 1.5 * 2.0  # 40 spikes of 80 mm inflate mean squares


def test_fit_noise_feeds_the_estimator():
    fit = fit_noise(simulate_model("ca", 1e7, 1.0, 5000, seed=11), DT, "ca")
    est = KalmanEstimator(**fit)
    assert est.model == "ca" and est.process_noise == fit["process_noise"]


@pytest.mark.parametrize(
    ("args", "options", "message"),
    [
        ((np.zeros(100), 0.01), {"model": "x"}, r"fit_noise: model must be one of \['cv', 'ca'\], got 'x'"),
        ((np.zeros(100), 0.0), {}, r"fit_noise: dt must be a finite number in \(0.0, inf\), got 0.0"),
        ((np.zeros(100), 0.01), {"max_lag": 0}, r"fit_noise: max_lag must be an integer >= 1, got 0"),
        ((np.zeros(30), 0.01), {}, r"fit_noise: positions must hold at least 52 samples for max_lag=16, got 30"),
        ((np.zeros((100, 2, 2)), 0.01), {}, r"fit_noise: positions must have shape \(T,\) or \(T, n\)"),
        ((np.zeros(100), 0.01), {}, r"fit_noise: the positions do not vary"),
        ((np.full(100, np.nan), 0.01), {}, r"fit_noise: too few finite samples .* at lag 1"),
    ],
)
def test_fit_noise_bad_arguments(args, options, message):
    with pytest.raises(ValueError, match=message):
        fit_noise(*args, **options)
