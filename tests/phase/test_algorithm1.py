"""The 1D phase estimator (Algorithm 1), its Hilbert reference and the synthetic oscillation generator."""

import math

import numpy as np
import pytest
import scipy.signal

from cogblocks.blocks import LowPass, Playback, Probe
from cogblocks.blocks.angles import TWO_PI, wrap_pi
from cogblocks.data.oscillation import generate_oscillation
from cogblocks.phase import Algorithm1Phase, PhaseEstimator, hilbert_phase
from cogblocks.sim import Diagram, DiagramError, Simulator

DT = 0.01


def run_estimator(position, **params):
    """Run a PhaseEstimator on a position array; returns (theta, amp_p, amp_v), one row per tick."""
    sim = Simulator(
        PhaseEstimator(**params),
        DT,
        probes={"theta": "algorithm.theta", "amp_p": "algorithm.amp_p", "amp_v": "algorithm.amp_v"},
    )
    trace = sim.run(n_steps=len(position), inputs={"p": np.asarray(position, dtype=float)})
    return trace["theta"], trace["amp_p"], trace["amp_v"]


def run_leaf(position, **params):
    """Run Algorithm1Phase alone (no filter in front: p and raw are the same signal)."""
    d = Diagram()
    src = d.add("src", Playback(position, unit="mm"))
    alg = d.add("alg", Algorithm1Phase(**params))
    d.connect(src.y, alg.p, alg.raw)
    trace = Simulator(d, DT, probes={"theta": "alg.theta", "amp_p": "alg.amp_p"}).run(n_steps=len(position))
    return trace["theta"], trace["amp_p"]


def cosine(f=0.8, amplitude=150.0, offset=300.0, seconds=12.0):
    t = np.arange(round(seconds / DT)) * DT
    return t, offset + amplitude * np.cos(TWO_PI * f * t)


# -- accuracy on clean signals ---------------------------------------------------


@pytest.mark.parametrize("f", [0.5, 0.8, 1.2])
def test_clean_cosine_converges_to_omega_t(f):
    t, p = cosine(f)
    theta, amp_p, amp_v = run_estimator(p)
    err = np.abs(wrap_pi(theta - TWO_PI * f * t))
    # after two periods (the centring window needs one, the amplitudes half of one) what is left
    # is the sampling of the extrema and crossings and the quarter-step velocity lag (~0.02 rad);
    # without the lag compensation the 3 Hz filter alone would lag 0.24-0.6 rad here
    settled = t >= 2.0 / f
    assert err[settled].max() < 0.05
    np.testing.assert_allclose(amp_p[-1], [150.0, 150.0], rtol=0.02)
    np.testing.assert_allclose(amp_v[-1], [150.0 * TWO_PI * f] * 2, rtol=0.05)


def test_lag_compensation_is_what_makes_the_bound():
    f = 1.2
    t, p = cosine(f)
    theta, _, _ = run_estimator(p, compensate=False)
    err = np.abs(wrap_pi(theta - TWO_PI * f * t))[t >= 2.0 / f]
    assert err.mean() > 0.4  # the 3 Hz Butterworth lags 0.59 rad at 1.2 Hz


def test_hilbert_phase_convention_matches_the_cosine():
    f = 0.8
    t, p = cosine(f, seconds=20.0)
    ref = hilbert_phase(p)
    assert ref.min() >= 0.0 and ref.max() < TWO_PI
    middle = (t > 3.0) & (t < 17.0)
    assert np.abs(wrap_pi(ref - TWO_PI * f * t))[middle].max() < 0.01
    # the same phase advances for a sine (a quarter turn later)
    ref_sin = hilbert_phase(np.sin(TWO_PI * f * t))
    assert np.abs(wrap_pi(ref_sin - (TWO_PI * f * t - np.pi / 2)))[middle].max() < 0.01


def test_online_agrees_with_hilbert_on_clean_data():
    osc = generate_oscillation(
        30.0, seed=4, noise_std=0.0, harmonics=0.0, dropout_rate=0.0, offset_drift=0.0, amplitude_drift=0.05
    )
    theta, _, _ = run_estimator(osc.position)
    err = np.abs(wrap_pi(theta - hilbert_phase(osc.position)))[(osc.t > 5.0) & (osc.t < 25.0)]
    assert err.mean() < 0.03
    assert err.max() < 0.15


def test_hilbert_phase_rejects_bad_input():
    with pytest.raises(ValueError, match="hilbert_phase: p must be finite; it has 1 NaN/inf sample"):
        hilbert_phase([1.0, np.nan, 2.0])
    with pytest.raises(ValueError, match=r"hilbert_phase: p must be a 1-D array of at least 2 samples, got shape"):
        hilbert_phase(np.zeros((2, 2)))
    with pytest.raises(ValueError, match=r"hilbert_phase: highpass must be a finite number in \(0.0, 50.0\), got 80"):
        hilbert_phase(np.zeros(10), highpass=80)


# -- bad data ------------------------------------------------------------------------


@pytest.mark.parametrize("value", [0.0, 123.4])
def test_constant_input_gives_phase_zero_and_no_nan(value):
    theta, amp_p, amp_v = run_estimator(np.full(300, value))
    assert np.all(theta == 0.0)
    assert np.all(np.isfinite(amp_p)) and np.all(np.isfinite(amp_v))


def test_no_nan_from_the_first_tick_on_messy_data():
    osc = generate_oscillation(30.0, seed=7, dropout_rate=10.0, nan_rate=0.02)
    theta, amp_p, amp_v = run_estimator(osc.position)
    assert np.all(np.isfinite(theta)) and np.all((theta >= 0.0) & (theta < TWO_PI))
    assert np.all(np.isfinite(amp_p)) and np.all(np.isfinite(amp_v))


def test_nan_first_sample_holds_the_initial_output():
    _, p = cosine()
    p[:3] = np.nan
    theta, amp_p, _ = run_estimator(p[:50])
    assert np.all(theta[:3] == 0.0) and np.all(amp_p[:3] == 0.0)
    assert np.all(np.isfinite(theta))


def test_flat_dropout_coasts_and_recovers_within_a_period():
    f = 0.8
    t, p = cosine(f, seconds=14.0)
    frozen = (t >= 6.56) & (t < 7.06)  # 0.5 s from a downward zero crossing, where the speed is largest
    p[frozen] = p[np.argmax(frozen) - 1]
    theta, amp_p, amp_v = run_estimator(p)
    err = np.abs(wrap_pi(theta - TWO_PI * f * t))
    assert np.all(np.isfinite(theta))
    # during the drop-out the phase coasts at the estimated frequency instead of stopping
    assert err[(t >= 6.5) & (t < 7.3)].max() < 0.1
    steps = np.abs(wrap_pi(np.diff(theta)))[(t[1:] >= 6.5) & (t[1:] < 9.0)]
    assert steps.max() < 0.2  # no jump: one tick at 0.8 Hz is 0.05 rad
    # amplitudes keep sensible values (the frozen value is at the centre: no collapse towards 0)
    assert amp_p[t >= 6.5].min() > 0.8 * 150.0 and amp_v[t >= 6.5].min() > 0.8 * 150.0 * TWO_PI * f
    assert err[t >= 7.06 + 1.0 / f].max() < 0.05


def run_filtered(position, *, remove_transient, holdoff=0.0):
    """LowPass(3 Hz, repeating through gaps) in front of Algorithm1Phase, built by hand."""
    d = Diagram()
    src = d.add("src", Playback(position, unit="mm"))
    lowpass = d.add("lowpass", LowPass(3.0, gaps="repeat"))
    alg = d.add("alg", Algorithm1Phase(cutoff=3.0, holdoff=holdoff, remove_transient=remove_transient))
    d.connect(src.y, lowpass.u, alg.raw)
    d.connect(lowpass.y, alg.p)
    probe = d.add("probe", Probe())
    d.connect(alg.theta, probe.u)
    return Simulator(d, DT).run(n_steps=len(position))["probe"]


@pytest.mark.parametrize("gap", ["frozen", "nan"])
def test_filter_transient_after_a_dropout_is_removed(gap):
    """After a 0.5 s gap in mid-swing the filter's transient is removed, not waited out (no hold-off at all).

    Without the removal the same chain is off by more than 0.5 rad after the gap (the filter was fed the
    frozen value for half a second); with it the error stays that of the extrapolation.
    """
    f = 0.8
    t, p = cosine(f, seconds=14.0)
    bad = (t >= 6.56) & (t < 7.06)  # from a downward zero crossing, where the speed is largest
    p[bad] = p[np.argmax(bad) - 1] if gap == "frozen" else np.nan
    after = (t >= 7.06) & (t < 7.06 + 1.0 / f)
    errors = {}
    for remove in (True, False):
        errors[remove] = np.abs(wrap_pi(run_filtered(p, remove_transient=remove) - TWO_PI * f * t))[after].max()
    assert errors[True] < 0.1
    assert errors[False] > 0.5


def test_remove_transient_needs_the_filter_it_removes():
    with pytest.raises(ValueError, match="remove_transient needs a cutoff"):
        Algorithm1Phase(remove_transient=True)


def test_flat_dropout_without_coasting_would_fail():
    """The same drop-out with the freeze detection off (min_dropout longer than it) goes wrong."""
    f = 0.8
    t, p = cosine(f, seconds=14.0)
    frozen = (t >= 6.56) & (t < 7.06)
    p[frozen] = p[np.argmax(frozen) - 1]
    theta, _, _ = run_estimator(p, min_dropout=1.0)
    err = np.abs(wrap_pi(theta - TWO_PI * f * t))
    assert err[(t >= 6.5) & (t < 7.3)].max() > 0.5


#: what the algorithm rebuilds through a gap from the filter's corrected output (``remove_transient``)
RECONSTRUCTED = {"gap_z", "p_prev", "pc_prev", "v_prev", "v_hist", "v_pos", "csum", "n_pushed", "total"}


def test_nan_sample_extrapolates_the_phase_and_holds_amplitudes_and_state():
    """A missing sample: θ moves on at the estimated frequency (held is set), nothing else advances.

    Except the low-pass, which is fed its last finite sample again (``gaps="repeat"``), and the
    algorithm's filtered position and its differences, rebuilt from the filter's output and its
    response to the gap (``remove_transient``).
    """
    _, p = cosine(seconds=5.0)
    compiled = PhaseEstimator().compile(DT)
    for x in p[:250]:
        before = compiled.step(p=x)
    assert not before["held"]
    state = compiled.state_dict()
    omega = state["blocks"]["algorithm"]["state"]["omega"]
    assert omega == pytest.approx(TWO_PI * 0.8, rel=0.02)
    for n, bad in enumerate((np.nan, np.inf, 1e308), start=1):
        out = compiled.step(p=bad)
        assert out["held"]
        assert out["theta"] == pytest.approx((before["theta"] + n * omega * DT) % TWO_PI, abs=1e-12)
        np.testing.assert_array_equal(out["amp_p"], before["amp_p"])
        np.testing.assert_array_equal(out["amp_v"], before["amp_v"])
        after = compiled.state_dict()
        for path in state["blocks"]:
            for name, value in state["blocks"][path]["state"].items():
                if (path, name) in {("algorithm", "phase"), ("algorithm", "since"), ("algorithm", "coast")}:
                    continue  # the extrapolation's own clock
                if path == "lowpass" and name == "z" or path == "algorithm" and name in RECONSTRUCTED:
                    continue  # the filter runs on the repeated sample (checked below); its output is corrected
                np.testing.assert_array_equal(after["blocks"][path]["state"][name], value, err_msg=f"{path}.{name}")
    sos = scipy.signal.butter(2, 3.0, fs=1.0 / DT, output="sos")
    fed = np.concatenate([p[:250], np.full(3, p[249])])
    _, z = scipy.signal.sosfilt(sos, fed, zi=scipy.signal.sosfilt_zi(sos) * p[0])
    np.testing.assert_allclose(after["blocks"]["lowpass"]["state"]["z"], z, rtol=1e-9, atol=1e-9)


def test_acceleration_check_rejects_an_inflection_plateau():
    """A maximum candidate (v from >= 0 to < 0, p above the centre) reached from below.

    Two periods of a cosine, a drop-out at the maximum (which resets the max/min alternation), then
    a descent through an inflection plateau: the velocity decays to exactly 0 (a repeated sample)
    and grows again in the same direction. With the default acceleration window the acceleration
    there is positive (the arm decelerated into the plateau) and A_p+ keeps the true maximum; with
    a one-sample acceleration (as in the original) the check is void and A_p+ drops to the plateau.
    """
    t = np.arange(520) * DT
    p = 100.0 * np.cos(np.pi * t)  # 2 s period, maximum 100 at t = 4.0
    p[401:431] = p[400]  # drop-out at the maximum
    tau = t[431:] - 4.56
    p[431:] = 60.0 - 40.0 * np.sign(tau) * np.abs(tau / 0.25) ** 3  # from 100 down to the plateau at 60, and on
    k = 456
    p[k + 1 :] = p[k:-1].copy()  # repeat the plateau sample: v = 0 exactly
    _, amp_default = run_leaf(p)
    _, amp_one_step = run_leaf(p, accel_window=0.0)
    assert amp_default[k - 5, 0] == pytest.approx(100.0, abs=2.0)  # the maximum, less the centre
    assert amp_default[-1, 0] == amp_default[k - 5, 0]
    assert amp_one_step[-1, 0] < 90.0  # the erroneous update the check prevents


# -- parameters ------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"cutoff": -1.0}, r"PhaseEstimator: cutoff must be a finite number in \(0.0, inf\), got -1.0"),
        ({"order": 0}, r"PhaseEstimator: order must be an integer >= 1, got 0"),
        ({"centre_periods": 1.5}, r"Algorithm1Phase: centre_periods must be an integer >= 1, got 1.5"),
        ({"accel_window": -0.1}, r"Algorithm1Phase: accel_window must be a finite number in \[0.0, inf\), got -0.1"),
        ({"min_dropout": math.nan}, r"Algorithm1Phase: min_dropout must be a finite number in \[0.0, inf\), got nan"),
        ({"holdoff": "long"}, r"Algorithm1Phase: holdoff must be a finite number in \[0.0, inf\), got 'long'"),
        ({"max_period": 0.0}, r"Algorithm1Phase: max_period must be a finite number in \(0.0, inf\), got 0.0"),
        ({"compensate": "yes"}, r"PhaseEstimator: compensate must be True or False, got 'yes'"),
        ({"unit": ""}, r"Algorithm1Phase: unit must be a non-empty string, got ''"),
    ],
)
def test_parameter_errors_name_the_parameter(params, message):
    with pytest.raises(ValueError, match=message):
        PhaseEstimator(**params)


def test_cutoff_above_nyquist_fails_at_compile_time():
    with pytest.raises(DiagramError, match=r"cutoff 60.0 Hz must be below the Nyquist frequency 50 Hz"):
        PhaseEstimator(cutoff=60.0).compile(DT)


def test_ports_are_typed():
    est = PhaseEstimator(unit="m")
    est.compile(DT)
    assert est.p.spec.unit == "m" and est.p.spec.shape == ()
    assert est.theta.spec.unit == "rad" and est.theta.spec.wrapped
    assert est.amp_p.spec.unit == "m" and est.amp_p.spec.shape == (2,)
    assert est.amp_v.spec.unit == "m/s" and est.amp_v.spec.shape == (2,)


# -- inside a diagram ------------------------------------------------------------------------


def build_diagram(position):
    d = Diagram()
    src = d.add("src", Playback(position, unit="mm"))
    est = d.add("phase", PhaseEstimator())
    d.connect(src.y, est.p)
    d.add("theta", Probe())
    d.add("amp", Probe())
    d.connect(est.theta, "theta.u")
    d.connect(est.amp_p, "amp.u")
    return d


def test_runs_in_a_diagram_and_state_dict_round_trip_continues_identically():
    osc = generate_oscillation(20.0, seed=2, nan_rate=0.01, dropout_rate=10.0)
    sim = Simulator(build_diagram(osc.position), DT)
    first = sim.run(duration=8.0)
    snapshot = sim.state_dict()
    cont = sim.run(duration=8.0)
    sim.load_state_dict(snapshot)
    again = sim.run(duration=8.0)
    np.testing.assert_array_equal(cont["theta"], again["theta"])
    np.testing.assert_array_equal(cont["amp"], again["amp"])
    whole = Simulator(build_diagram(osc.position), DT).run(duration=16.0)
    np.testing.assert_array_equal(np.concatenate([first["theta"], cont["theta"]]), whole["theta"])
    # and it tracks the oscillation (drop-outs and missing samples included)
    err = np.abs(wrap_pi(whole["theta"] - osc.phase[: len(whole.t)]))[whole.t > 5.0]
    assert err.mean() < 0.2


def test_runs_at_a_slower_period():
    f = 0.8
    t = np.arange(1200) * DT
    p = 150.0 * np.cos(TWO_PI * f * t)
    d = Diagram()
    src = d.add("src", Playback(p, unit="mm"))
    est = d.add("phase", PhaseEstimator(period=0.02))
    d.connect(src.y, est.p)
    d.add("theta", Probe())
    d.connect(est.theta, "theta.u")
    theta = Simulator(d, DT).run(n_steps=len(p))["theta"]
    err = np.abs(wrap_pi(theta - TWO_PI * f * t))[::2]  # the block's own ticks (it holds in between)
    assert err[t[::2] > 3.0].max() < 0.05


# -- the generator ------------------------------------------------------------------------


def test_generator_is_seeded():
    a = generate_oscillation(20.0, seed=11, nan_rate=0.01)
    b = generate_oscillation(20.0, seed=11, nan_rate=0.01)
    c = generate_oscillation(20.0, seed=12, nan_rate=0.01)
    for field in ("position", "phase", "dropout", "clean", "frequency", "amplitude"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
    assert not np.allclose(a.clean, c.clean)


def test_generator_dropout_mask_is_honoured():
    osc = generate_oscillation(600.0, seed=5, dropout_rate=6.0)
    mask = osc.dropout
    idx = np.flatnonzero(mask)
    assert np.all(osc.position[idx] == osc.position[idx - 1])  # frozen: repeats the sample before
    np.testing.assert_array_equal(osc.position[~mask], osc.clean[~mask])
    starts = np.flatnonzero(np.diff(mask.astype(int)) == 1) + 1
    stops = np.flatnonzero(np.diff(mask.astype(int)) == -1) + 1
    lengths = (stops - starts[: len(stops)]) * osc.dt
    assert 30 <= len(starts) <= 90  # about 6 a minute for 10 minutes (some overlap and merge)
    assert lengths.min() >= 0.1 - 1e-9 and np.median(lengths) <= 0.5
    assert not generate_oscillation(60.0, seed=5, dropout_rate=0.0).dropout.any()


def test_generator_ranges():
    osc = generate_oscillation(120.0, seed=8, nan_rate=0.05)
    assert osc.t[1] - osc.t[0] == pytest.approx(0.01) and len(osc.t) == 12000
    assert osc.frequency.min() >= 0.4 and osc.frequency.max() <= 1.2
    assert osc.amplitude.min() >= 100.0 and osc.amplitude.max() <= 300.0
    assert osc.phase.min() >= 0.0 and osc.phase.max() < TWO_PI
    assert 0.03 < np.isnan(osc.position).mean() < 0.07
    assert np.all(np.isfinite(osc.clean))
    swing = osc.clean - np.convolve(osc.clean, np.ones(500) / 500, mode="same")
    assert 90.0 < np.abs(swing[500:-500]).max() < 400.0


def test_generator_phase_is_the_phase_of_the_position():
    osc = generate_oscillation(
        30.0, seed=9, noise_std=0.0, harmonics=0.0, offset_drift=0.0, amplitude_drift=0.0, dropout_rate=0.0
    )
    centred = osc.clean - osc.clean.mean()
    np.testing.assert_allclose(centred, osc.amplitude * np.cos(osc.phase), atol=1.0)


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"duration": 0.0}, r"generate_oscillation: duration must be a finite number in \(0.0, inf\), got 0.0"),
        ({"freq_range": (1.2, 0.4)}, r"generate_oscillation: freq_range must be a pair \(lo, hi\) with 0.0 < lo <= hi"),
        ({"freq_range": (0.4, 80.0)}, r"freq_range must be a pair \(lo, hi\) with 0.0 < lo <= hi <= 50.0, got"),
        ({"amplitude_range": 100.0}, r"generate_oscillation: amplitude_range must be a pair"),
        ({"harmonics": 0.5}, r"generate_oscillation: harmonics must be a finite number in \[0.0, 0.3\], got 0.5"),
        ({"nan_rate": 1.0}, r"generate_oscillation: nan_rate must be a finite number in \[0.0, 1.0\), got 1.0"),
        ({"dropout_duration": (0.0, 0.5)}, r"generate_oscillation: dropout_duration must be a pair"),
        ({"noise_std": -1.0}, r"generate_oscillation: noise_std must be a finite number in \[0.0, inf\), got -1.0"),
    ],
)
def test_generator_parameter_errors(params, message):
    with pytest.raises(ValueError, match=message):
        generate_oscillation(**params)
