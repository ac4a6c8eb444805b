"""The λ report of the Blender against closed forms and against simulation of the block."""

import contextlib
import math

import numpy as np
import pytest

from cogblocks.blocks import Playback
from cogblocks.sim import Diagram, DiagramError, Simulator
from cogblocks.sync import Blender, check_blender, lambda_report

FAR = 2.5  # reference offset beyond any λ_max used here: the blender sits at its limit
#: Section 5.2.3.2's values.
DELIVERABLE_VALUES = dict(
    lam_min=0.3 * math.pi / 2, lam_max=math.pi / 2, e_max=0.3 * math.pi / 2, kappa_plus=1.0, kappa_minus=2.5
)
STEEP = dict(lam_min=0.2, lam_max=1.0, e_max=0.8, kappa_plus=1.0, kappa_minus=2.5)  # λ* = 0.5 < e_max


def simulate(blender, n_far, n_back, dt=0.01):
    """λ[k] with θ_L0 = 0 and θ_ref = FAR for n_far ticks, then θ_ref = θ_L0 for n_back ticks."""
    d = Diagram()
    l0 = d.add("l0", Playback(np.zeros(n_far + n_back), unit="rad", wrapped=True))
    ref = d.add("ref", Playback(np.r_[np.full(n_far, FAR), np.zeros(n_back)], unit="rad", wrapped=True))
    bl = d.add("bl", blender)
    d.connect(l0.y, bl.theta_l0)
    d.connect(ref.y, bl.theta_ref)
    return Simulator(d, dt=dt, probes=["bl.lam"]).run(n_steps=n_far + n_back)["bl.lam"]


def settling_tick(lam, target, band):
    """First tick after which |λ − target| stays within band."""
    outside = np.flatnonzero(np.abs(lam - target) > band)
    return int(outside[-1]) + 1 if outside.size else 0


def closed_form(lam_min, lam_max, e_max):
    delta = lam_max - lam_min
    lam = (delta + lam_min) / (1 + delta / e_max)
    return lam if lam < e_max else lam_min


@pytest.mark.parametrize(
    "params",
    [
        DELIVERABLE_VALUES,
        STEEP,
        dict(lam_min=0.6, lam_max=1.2, e_max=0.5),  # λ∞ reaches λ_min before the bisector
        dict(lam_min=0.1, lam_max=0.3, e_max=1.0),  # λ_max below e_max: a single linear piece
        dict(lam_min=0.4, lam_max=0.4, e_max=1.0),  # constant λ
    ],
)
def test_lambda_star_matches_the_closed_form_of_the_triangular_psi(params):
    report = lambda_report(Blender(**params))
    expected = closed_form(params["lam_min"], params["lam_max"], params["e_max"])
    assert report.lam_star == pytest.approx(expected, abs=1e-12)


def test_deliverable_numbers():
    report = lambda_report(Blender())
    e_max = 0.3 * math.pi / 2
    assert report.lam_star == pytest.approx(e_max, abs=1e-12)  # λ_min = e_max: λ* sits on the kink of ψ
    assert report.slope_below == pytest.approx(-(math.pi / 2 - e_max) / e_max)
    assert report.slope_above == 0.0
    assert report.multiplier_below == pytest.approx(1 - 0.01 * (1 + 7 / 3))
    assert report.multiplier_above == pytest.approx(1 - 0.01 * 2.5)
    assert report.stable and report.monotone and report.locally_stable and report.locally_monotone
    # (1 − 0.025)^n <= 0.02 and (1 − 0.01)^n <= 0.02
    assert report.settle_down == pytest.approx(0.01 * math.ceil(math.log(0.02) / math.log(0.975)))
    assert report.settle_up == pytest.approx(0.01 * math.ceil(math.log(0.02) / math.log(0.99)))
    assert "λ* = 0.471239" in str(report)


def test_bump_psi_has_a_root_on_the_bisector_between_the_bounds():
    blender = Blender(**STEEP, psi="bump")
    report = lambda_report(blender)
    assert blender.lam_inf(report.lam_star) == pytest.approx(report.lam_star, abs=1e-12)
    assert STEEP["lam_min"] < report.lam_star < STEEP["e_max"]
    # one smooth slope, seen from both sides
    assert report.slope_below == pytest.approx(report.slope_above, rel=1e-6)
    h = 1e-6
    slope = (blender.lam_inf(report.lam_star + h) - blender.lam_inf(report.lam_star - h)) / (2 * h)
    assert report.slope_above == pytest.approx(slope, rel=1e-6)


@pytest.mark.parametrize(
    "params",
    [
        dict(DELIVERABLE_VALUES),
        dict(DELIVERABLE_VALUES, psi="bump"),
        dict(STEEP),
        dict(STEEP, psi="bump"),
        dict(STEEP, kappa_minus=60.0),  # dt κ⁻ = 0.6 but the multiplier above λ* is −0.2: iterated
        dict(lam_min=0.1, lam_max=0.3, e_max=1.0),  # a single sloped piece
    ],
)
def test_report_against_simulation_of_the_block(params):
    blender = Blender(**params)
    report = lambda_report(blender)
    n_far, n_back = 1500, 1000
    # the block checks its parameters when compiled: an overshooting λ is only warned about
    overshoots = min(report.multiplier_below, report.multiplier_above) < 0
    with pytest.warns(RuntimeWarning, match="oscillates around") if overshoots else contextlib.nullcontext():
        lam = simulate(blender, n_far, n_back)
    assert lam[n_far - 1] == pytest.approx(report.lam_star, abs=1e-9)
    band = report.tolerance * (report.lam_max - report.lam_star)
    measured_down = settling_tick(lam[:n_far], report.lam_star, band) * 0.01
    assert abs(measured_down - report.settle_down) <= 0.01 + 1e-12
    back = lam[n_far:]
    assert back[0] == pytest.approx(report.lam_star, abs=1e-9)
    measured_up = settling_tick(back, report.lam_max, report.tolerance * (report.lam_max - back[0])) * 0.01
    assert abs(measured_up - report.settle_up) <= 0.01 + 1e-12


def test_multiplier_is_the_simulated_local_rate_above_lambda_star():
    report = lambda_report(Blender(**STEEP))
    lam = simulate(Blender(**STEEP), 400, 0)
    err = lam - report.lam_star
    ratios = err[200:300] / err[199:299]
    np.testing.assert_allclose(ratios, report.multiplier_above, rtol=1e-6)
    assert report.multiplier_above == pytest.approx(1 - 0.01 * 2.5 * (1 + 0.8 / 0.8))


def test_unstable_equilibrium_is_reported_and_refused():
    # dt κ± < 1 on both linear pieces, but λ∞ is so steep at λ* that the saturated map
    # has multipliers −1.25 and −2.75: λ oscillates for ever, so the block refuses to compile
    params = dict(lam_min=0.1, lam_max=1.4, e_max=0.2, kappa_plus=3.0, kappa_minus=5.0)
    report = lambda_report(Blender(**params), dt=0.1)
    assert report.stable and report.monotone
    assert report.lam_star == pytest.approx(1.4 / 7.5)
    assert report.multiplier_below == pytest.approx(1 - 0.3 * 7.5)
    assert report.multiplier_above == pytest.approx(1 - 0.5 * 7.5)
    assert not report.locally_stable and report.settle_down == math.inf
    with pytest.raises(ValueError, match="kappa_minus"):
        check_blender(Blender(**params), dt=0.1)
    with pytest.raises(DiagramError, match="the equilibrium at the limit"):
        simulate(Blender(**params), 300, 0, dt=0.1)
    # the saturated map itself, iterated by hand: e = λ, so λ ← λ − dt κ (λ − λ∞(λ))
    blender, lam = Blender(**params), [1.4]
    for _ in range(299):
        target = blender.lam_inf(lam[-1])
        kappa = 3.0 if lam[-1] <= target else 5.0
        lam.append(lam[-1] - 0.1 * kappa * (lam[-1] - target))
    lam = np.array(lam)
    assert np.ptp(lam[-50:]) > 0.05  # still swinging after 25 s
    assert np.all(np.abs(lam[-50:] - report.lam_star) > 1e-3)


def test_check_blender_refuses_dt_kappa_of_two_or_more():
    with pytest.raises(ValueError, match="kappa_minus"):
        check_blender(Blender(kappa_minus=200.0), dt=0.01)
    with pytest.raises(ValueError, match="kappa_plus"):
        check_blender(Blender(kappa_plus=250.0, kappa_minus=300.0), dt=0.01)


def test_check_blender_warns_when_lambda_overshoots():
    with pytest.warns(RuntimeWarning) as caught:
        report = check_blender(Blender(kappa_minus=150.0), dt=0.01)
    messages = [str(w.message) for w in caught]
    assert any("dt * kappa_minus = 1.5" in m for m in messages)
    assert any("oscillates around" in m for m in messages)  # the multiplier above λ* is 1 − 1.5
    assert report.stable and not report.monotone and report.locally_stable
    with pytest.warns(RuntimeWarning, match="oscillates around"):
        check_blender(Blender(**dict(STEEP, kappa_minus=60.0)), dt=0.01)


def test_check_blender_is_silent_for_the_deliverable():
    report = check_blender(Blender(), dt=0.01)
    assert report.lam_star == pytest.approx(DELIVERABLE_VALUES["e_max"])


def test_overshooting_settling_time_against_simulation():
    # dt κ⁻ = 1.5: λ jumps across λ∞ each tick; the settling time comes from iterating the map
    with pytest.warns(RuntimeWarning):
        blender = Blender(kappa_minus=150.0)
        report = lambda_report(blender)
        lam = simulate(blender, 300, 0)
    band = report.tolerance * (report.lam_max - report.lam_star)
    assert abs(settling_tick(lam, report.lam_star, band) * 0.01 - report.settle_down) <= 0.01 + 1e-12
