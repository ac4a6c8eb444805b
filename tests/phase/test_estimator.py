"""The 1D estimator's rules at any rate and in any unit: drop-outs, the held output, extrapolation, spikes."""

import warnings

import numpy as np
import pytest

from cogblocks.blocks.angles import TWO_PI, wrap_pi
from cogblocks.data.sensor import simulate_sensor
from cogblocks.evaluation.phase1d import evaluate_grid
from cogblocks.phase import PhaseEstimator
from cogblocks.sim import Simulator


def run(p, rate, **params):
    trace = Simulator(PhaseEstimator(**params), 1.0 / rate, probes={"theta": "theta", "held": "held"}).run(
        n_steps=len(p), inputs={"p": np.asarray(p, dtype=float)}
    )
    return trace["theta"], trace["held"]


def cosine(rate, f=0.7, seconds=14.0, amplitude=1.0, offset=3.0):
    t = np.arange(round(seconds * rate)) / rate
    return t, offset + amplitude * np.cos(TWO_PI * f * t)


@pytest.mark.parametrize("rate", [25.0, 40.0, 240.0])
def test_quantised_repeats_are_data_not_drop_outs(rate):
    """A 5 % quantisation step repeats samples in runs (1-4 at mid-swing, longer at the extrema): never held."""
    t, p = cosine(rate)
    q = np.round(p / 0.05) * 0.05
    runs = np.diff(np.flatnonzero(np.diff(np.r_[np.inf, q, np.inf]) != 0.0))
    assert runs.max() >= 3  # the signal does repeat
    theta, held = run(q, rate)
    assert not held.any()
    settled = t >= 2.0 / 0.7
    assert np.abs(wrap_pi(theta - TWO_PI * 0.7 * t))[settled].mean() < 0.1


@pytest.mark.parametrize("rate", [25.0, 100.0, 240.0])
def test_a_freeze_in_mid_swing_is_a_drop_out_within_a_few_samples(rate):
    t, p = cosine(rate)
    start = np.searchsorted(t, 7.0 + 0.25 / 0.7)  # a downward zero crossing: the fastest point
    stop = start + round(0.4 * rate)
    p[start:stop] = p[start - 1]
    theta, held = run(p, rate)
    assert not held[: start - 1].any()
    # confirmed after at least two repeats, and at 30 ms (min_dropout) at high rates
    first = start + np.argmax(held[start:])
    assert held[first:stop].all() and first - start <= max(2, round(0.03 * rate))
    err = np.abs(wrap_pi(theta - TWO_PI * 0.7 * t))
    assert err[start:stop].max() < 0.1  # extrapolated through it, the unconfirmed repeats rewound
    assert err[stop + round(rate / 0.7) :].max() < 0.1


def test_a_freeze_at_an_extremum_is_recognised_by_its_length():
    """Quantised, a repeat at an extremum is normal: only rule (a), a quarter period, confirms the drop-out."""
    rate, f = 60.0, 0.7
    t, p = cosine(rate, f=f)
    p = np.round(p / 0.05) * 0.05
    start = np.searchsorted(t, 5.0 / f)  # the fifth maximum
    stop = start + round(0.6 * rate)
    p[start:stop] = p[start]
    theta, held = run(p, rate)
    assert not held[:start].any()
    first = start + np.argmax(held[start:])
    # the run began on the plateau a little before the maximum; a quarter period is 21 samples
    assert 0.1 * rate / f <= first - start <= 0.26 * rate / f
    assert held[first:stop].all()
    assert np.abs(wrap_pi(theta - TWO_PI * f * t))[first:stop].max() < 0.15


def test_the_same_movement_in_any_unit_gives_the_same_phase():
    small = simulate_sensor(20.0, rate_hz=40.0, seed=9, scale=0.01, quantisation=0.05)
    large = simulate_sensor(20.0, rate_hz=40.0, seed=9, scale=1000.0, quantisation=0.05)
    for front_end in ("lowpass", "kalman"):
        theta_small, held_small = run(small.value, 40.0, front_end=front_end)
        theta_large, held_large = run(large.value, 40.0, front_end=front_end)
        np.testing.assert_array_equal(held_small, held_large)
        assert np.abs(wrap_pi(theta_small - theta_large)).max() < 1e-6


def test_long_gap_extrapolates_for_max_coast_periods_then_holds():
    rate, f = 50.0, 0.7
    t, p = cosine(rate, f=f)
    start = round(7.0 * rate)
    p[start:] = np.nan
    theta, held = run(p, rate, max_coast=2.0)
    assert held[start:].all() and not held[:start].any()
    steps = wrap_pi(np.diff(theta[start - 1 :]))
    n_coast = round(2.0 * rate / f)
    np.testing.assert_allclose(steps[: n_coast - 5], TWO_PI * f / rate, rtol=0.03)
    assert np.all(steps[n_coast + 5 :] == 0.0)


def test_spikes_are_gated_and_absurd_values_raise_no_warning():
    rate = 100.0
    t, p = cosine(rate, amplitude=2.0)
    clean_theta, _ = run(p, rate)
    for k, value in ((500, 3.0 + 20.0), (800, 1e308), (900, -np.inf), (1000, np.nan), (1100, -1e200)):
        p[k] = value
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        theta, held = run(p, rate)
        run(p, rate, front_end="kalman")
    assert held[[500, 800, 900, 1000, 1100]].all()
    assert np.abs(wrap_pi(theta - clean_theta)).max() < 0.05


def test_a_tiny_grid_reports_every_cell():
    result = evaluate_grid(
        rates=(40.0,), scales=(1.0,), quantisations=("coarse",), noises=("low", "high"), seeds=(0,), duration=20.0
    )
    assert [(c["rate_hz"], c["noise"]) for c in result["cells"]] == [(40.0, "low"), (40.0, "high")]
    for cell in result["cells"]:
        assert 0.0 < cell["mean_error_rad"] < cell["p95_error_rad"] < np.pi
        assert 0.0 <= cell["held_share"] < 0.05
        assert cell["mean_error_rad"] < 0.2 and cell["hilbert_mean_error_rad"] < 0.2
    assert result["worst_mean_error_rad"] == max(c["mean_error_rad"] for c in result["cells"])
    assert result["worst_held_share"] == max(c["held_share"] for c in result["cells"])
    with pytest.raises(ValueError, match=r"evaluate_grid: noises must be among \['high', 'low'\], got \('loud',\)"):
        evaluate_grid(noises=("loud",))


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["run", "phase1d", "--signals", "11"], "--signals must be 1-10, --duration at least 10 s"),
        (["run", "phase1d", "--duration", "5"], "got 10, 5, 2"),
        (["run", "phase3d", "--rate", "20"], "--rate must be between 30 and 240 Hz, got 20"),
    ],
)
def test_cli_checks_its_grid_options(argv, message, capsys):
    from cogblocks.cli import main

    assert main(argv) == 2
    assert message in capsys.readouterr().err
