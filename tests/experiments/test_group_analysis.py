"""analyse_group on recordings synthesised with known phases: locked groups significant, independent ones not."""

from __future__ import annotations

import numpy as np
import pytest

from cogblocks.data.group_session import group_recording
from cogblocks.experiments.group_analysis import _shifted, analyse_group, order_parameter, surrogate_test

DT = 0.01
NAMES = [f"P{i}" for i in range(1, 6)]


def locked_phases(seed: int, n: int = 5, duration: float = 30.0) -> np.ndarray:
    """A group moving together at 0.5 Hz: one common phase, small fixed offsets, slow individual drifts."""
    rng = np.random.default_rng(seed)
    t = DT * np.arange(round(duration / DT))
    common = rng.uniform(0, 2 * np.pi) + np.pi * t + np.cumsum(rng.normal(0, 0.01, len(t)))
    return common + rng.normal(0, 0.3, (n, 1)) + np.cumsum(rng.normal(0, 0.005, (n, len(t))), axis=1)


def independent_phases(seed: int, n: int = 5, duration: float = 30.0) -> np.ndarray:
    """Oscillators that ignore each other: own tempo in 0.4-0.6 Hz, own start, own phase noise."""
    rng = np.random.default_rng(seed)
    t = DT * np.arange(round(duration / DT))
    tempo = rng.uniform(0.4, 0.6, (n, 1))
    return 2 * np.pi * tempo * t + rng.uniform(0, 2 * np.pi, (n, 1)) + np.cumsum(rng.normal(0, 0.02, (n, len(t))), 1)


def test_the_order_parameter_is_the_mean_resultant_length_of_the_participants_phases():
    theta = np.random.default_rng(0).uniform(0, 2 * np.pi, (4, 50))
    expected = [np.hypot(np.cos(theta[:, k]).mean(), np.sin(theta[:, k]).mean()) for k in range(50)]
    np.testing.assert_allclose(order_parameter(theta), expected, rtol=1e-12)


def test_a_shift_surrogate_rotates_each_participant_by_at_least_two_periods():
    theta = locked_phases(1, n=3)
    usable = np.ones(theta.shape, dtype=bool)
    usable[1, 100:120] = False
    surrogate, mask = _shifted(theta, usable, 200.0, np.random.default_rng(0))
    np.testing.assert_array_equal(surrogate[0], theta[0])  # the first participant stays
    for i in (1, 2):
        lag = next(k for k in range(theta.shape[1]) if np.array_equal(np.roll(theta[i], k), surrogate[i]))
        assert 400 <= lag <= theta.shape[1] - 400
        np.testing.assert_array_equal(mask[i], np.roll(usable[i], lag))


@pytest.mark.parametrize("seed", [100, 101, 102])
def test_a_locked_group_is_above_every_surrogate(seed):
    theta = locked_phases(seed)
    result = analyse_group(group_recording(theta, seed=seed), NAMES, online=False)
    test = result["offline"]
    assert test["r_mean"] == pytest.approx(order_parameter(theta).mean(), abs=0.02)  # the true phases' r
    assert test["r_mean"] > 0.85
    assert test["null_p95"] < 0.8  # random relative phases of 5 people rarely line up
    assert test["p_value"] <= 0.02  # at most 3 of 199 surrogates as synchronised: well inside 0.05
    assert test["above_chance"]


def test_independent_oscillators_are_not_above_chance():
    p = []
    for seed in range(200, 210):
        result = analyse_group(group_recording(independent_phases(seed), seed=seed), NAMES, online=False)
        p.append(result["offline"]["p_value"])
        assert result["offline"]["r_mean"] < 0.8
    # under the null p is uniform: 3 or more of 10 below 0.05 has probability 1.2 %, a median below 0.2 0.6 %
    assert sum(value <= 0.05 for value in p) <= 2
    assert np.median(p) > 0.2


def test_the_online_estimator_agrees_with_the_hilbert_reference_on_a_locked_group():
    theta = locked_phases(7, n=4, duration=20.0)
    result = analyse_group(group_recording(theta, seed=7), NAMES[:4])
    online, offline = result["online"], result["offline"]
    assert online["mean_error_vs_offline_rad"] < 0.1
    assert abs(online["r_mean"] - offline["r_mean"]) < 0.03
    assert online["above_chance"] and offline["above_chance"]
    # r(t) of the offline phases against the true phases' r(t) where it is defined
    series = result["series"]
    defined = ~np.isnan(series["r_offline"])
    np.testing.assert_allclose(series["r_offline"][defined], order_parameter(theta)[defined], atol=0.05)


def test_conditions_marked_by_events_are_tested_each_on_its_own_ticks():
    locked, independent = locked_phases(3), independent_phases(3)
    half = locked.shape[1] // 2
    # locked in the second half only (the L2 switched on at 15 s; everyone's phase jumps there)
    theta = np.concatenate([independent[:, :half], locked[:, half:]], axis=1)
    events = [("without_L2", 0.0), ("with_L2", half * DT)]
    result = analyse_group(group_recording(theta, seed=3, events=events), NAMES, online=False)
    without, with_l2 = result["conditions"]["without_L2"], result["conditions"]["with_L2"]
    assert without["duration_s"] == pytest.approx(15.0) and with_l2["duration_s"] == pytest.approx(15.0)
    assert with_l2["offline"]["above_chance"] and with_l2["offline"]["r_mean"] > 0.9
    assert not without["offline"]["above_chance"]
    assert with_l2["offline"]["r_mean"] > without["offline"]["r_mean"] + 0.3


def test_bad_requests_are_refused_by_name():
    rec = group_recording(locked_phases(0, n=2, duration=10.0))
    with pytest.raises(ValueError, match="at least 2 markers"):
        analyse_group(rec, ["P1"])
    with pytest.raises(ValueError, match=r"no marker\(s\) 'P7'"):
        analyse_group(rec, ["P1", "P7"])
    with pytest.raises(ValueError, match="n_surrogates must be an integer >= 19"):
        surrogate_test(np.zeros((2, 10)), np.ones((2, 10), dtype=bool), n_surrogates=5)


def test_an_occluded_participant_leaves_r_undefined_there_and_the_rest_counts():
    theta = locked_phases(11)
    rec = group_recording(theta, seed=11)
    points = rec.points.copy()
    points[1000:1200, 2] = np.nan  # P3 hidden for 2 s
    hidden = type(rec)(points, rec.t, rec.rate, rec.markers, rec.events, rec.source)
    result = analyse_group(hidden, NAMES, online=False)
    r = result["series"]["r_offline"]
    assert np.isnan(r[1000:1200]).all() and np.isfinite(r[400:950]).all() and np.isfinite(r[1250:2500]).all()
    assert result["offline"]["above_chance"]
    defined = ~np.isnan(r)
    np.testing.assert_allclose(r[defined], order_parameter(theta)[defined], atol=0.05)


def test_condition_times_are_read_on_the_files_clock_when_it_does_not_start_at_zero(tmp_path):
    ezc3d = pytest.importorskip("ezc3d")
    from cogblocks.data.c3d import write_c3d

    rec = group_recording(locked_phases(2, n=3, duration=20.0), seed=2)
    write_c3d(tmp_path / "late.c3d", rec.points, rec.markers, 100, events=[("a", 1.0), ("b", 11.0)])
    c3d = ezc3d.c3d(str(tmp_path / "late.c3d"))
    c3d["header"]["points"]["first_frame"] = 100  # the recording starts at 1 s on the file's clock
    c3d["header"]["points"]["last_frame"] = 2099
    c3d.write(str(tmp_path / "late.c3d"))
    result = analyse_group(tmp_path / "late.c3d", NAMES[:3], online=False)
    assert result["conditions"]["a"]["duration_s"] == pytest.approx(10.0)
    assert result["conditions"]["b"]["duration_s"] == pytest.approx(10.0)
