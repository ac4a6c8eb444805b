"""The Blender (eqs. 3–6) against hand-derived values and invariants."""

import math
import re

import numpy as np
import pytest

from cogblocks.blocks import Playback
from cogblocks.sim import Diagram, DiagramError, Simulator
from cogblocks.sync import DELIVERABLE, Blender


def run_blender(theta_l0, theta_ref, dt=0.01, **params):
    d = Diagram()
    a = d.add("l0", Playback(np.mod(theta_l0, 2 * np.pi), unit="rad", wrapped=True))
    b = d.add("ref", Playback(np.mod(theta_ref, 2 * np.pi), unit="rad", wrapped=True))
    bl = d.add("bl", Blender(**params))
    d.connect(a.y, bl.theta_l0)
    d.connect(b.y, bl.theta_ref)
    tr = Simulator(d, dt=dt, probes=["bl.theta_l2", "bl.lam"]).run(n_steps=len(theta_l0))
    return tr["bl.theta_l2"], tr["bl.lam"]


def circ(a, b):
    return np.abs(np.angle(np.exp(1j * (np.asarray(a) - np.asarray(b)))))


def test_small_offsets_pass_the_reference_through():
    t = np.arange(300) * 0.01
    l0 = 3.0 * t
    ref = l0 + 0.3 * np.sin(t)  # always within λ_min = 0.47
    l2, lam = run_blender(l0, ref)
    assert circ(l2, np.mod(ref, 2 * np.pi)).max() < 1e-12
    assert np.all((l2 >= 0) & (l2 < 2 * np.pi))


def test_alteration_never_exceeds_lambda_and_lambda_stays_in_bounds():
    rng = np.random.default_rng(0)
    l0 = np.cumsum(rng.normal(0.03, 0.05, 2000))
    ref = np.cumsum(rng.normal(0.05, 0.2, 2000))
    l2, lam = run_blender(l0, ref)
    assert np.all(circ(l2, l0) <= lam + 1e-12)
    p = DELIVERABLE
    assert np.all((lam >= p.lam_min - 1e-12) & (lam <= p.lam_max + 1e-12))
    assert lam[0] == pytest.approx(p.lam_max)


def test_lambda_settles_where_lambda_inf_meets_the_bisector():
    # λ* solves λ = (1 − λ/e_max)(λ_max − λ_min) + λ_min: 0.5 for these values
    params = dict(lam_min=0.2, lam_max=1.0, e_max=0.8, kappa_plus=1.0, kappa_minus=2.5)
    n = 3000
    l0 = np.zeros(n)
    ref = np.full(n, 2.0)  # far away: the blender sits at its limit, e = λ
    l2, lam = run_blender(l0, ref, **params)
    assert lam[-1] == pytest.approx(0.5, abs=1e-6)
    # while λ > λ∞ it decays toward λ∞(λ) with rate κ⁻: one Euler step by hand
    lam_inf0 = (1 - 1.0 / 0.8) * 0.8 + 0.2 if 1.0 < 0.8 else 0.2
    assert lam[1] == pytest.approx(1.0 - 0.01 * 2.5 * (1.0 - lam_inf0))
    np.testing.assert_allclose(circ(l2, l0), lam, atol=1e-12)


def test_lambda_recovers_at_kappa_plus_rate():
    params = dict(lam_min=0.2, lam_max=1.0, e_max=0.8, kappa_plus=1.0, kappa_minus=2.5)
    n = 1500
    l0 = np.zeros(n)
    ref = np.where(np.arange(n) < 500, 2.0, 0.0)  # far, then on top of θ_L0
    _, lam = run_blender(l0, ref, **params)
    # once e = 0, λ∞ = λ_max and λ rises as λ_max − (λ_max − λ)(1 − dt κ⁺)^n
    start = lam[501]
    expected = 1.0 - (1.0 - start) * (1 - 0.01) ** np.arange(n - 501)
    np.testing.assert_allclose(lam[501:], expected, rtol=1e-12)


def test_smooth_saturation_and_bump_psi_values():
    b = Blender(saturation="smooth", psi="bump")
    assert b.saturate(0.0, 1.0) == 0.0
    assert b.saturate(1.0, 1.0) == pytest.approx(1 / 2**0.25)
    assert b.saturate(100.0, 1.0) == pytest.approx(1.0, abs=1e-6)
    assert b.saturate(-3.0, 0.5) == pytest.approx(-3.0 / (1 + 6.0**4) ** 0.25)
    assert b.psi_of(0.0) == pytest.approx(1.0)
    assert b.psi_of(0.5) == pytest.approx(math.exp(1 - 1 / 0.75))
    assert b.psi_of(1.0) == 0.0 and b.psi_of(-2.0) == 0.0
    hard = Blender()
    assert hard.psi_of(0.25) == 0.75 and hard.saturate(2.0, 0.5) == 0.5


def test_bad_input_policies():
    l0 = np.full(6, 1.0)
    l0[2] = np.nan
    ref = np.full(6, 1.2)
    ref[4] = np.nan
    l2, lam = run_blender(l0, ref)
    _, clean_lam = run_blender(np.full(6, 1.0), np.full(6, 1.2))
    assert l2[2] == l2[1] and lam[2] == lam[1]  # outputs held
    assert lam[3] == clean_lam[2]  # λ did not advance during the bad tick
    assert l2[4] == pytest.approx(1.0)  # no reference: no alteration
    assert np.all(np.isfinite(l2)) and np.all(np.isfinite(lam))


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(lam_min=0.0), r"lam_min must be a finite number in \(0.0, inf\), got 0.0"),
        (dict(lam_min=1.0, lam_max=0.5), r"lam_max must be a finite number in \[1.0, inf\), got 0.5"),
        (dict(e_max=-1.0), r"e_max must be a finite number in \(0.0, inf\), got -1.0"),
        (dict(kappa_plus=0.0), r"kappa_plus must be a finite number in \(0.0, inf\), got 0.0"),
        (dict(kappa_minus=float("nan")), "kappa_minus must be a finite number"),
        (dict(saturation="soft"), r"saturation must be one of \['hard', 'smooth'\], got 'soft'"),
        (dict(psi="box"), r"psi must be one of \['triangular', 'bump'\], got 'box'"),
    ],
)
def test_parameter_errors(kwargs, message):
    with pytest.raises(ValueError, match="Blender: " + message):
        Blender(**kwargs)


def test_unstable_euler_step_is_refused_and_non_monotone_warns():
    with pytest.raises(DiagramError, match=r"bl: dt \* kappa_minus = 2.5 >= 2 makes the forward-Euler λ dynamics"):
        run_blender(np.zeros(3), np.zeros(3), dt=1.0, kappa_plus=0.5)
    with pytest.warns(RuntimeWarning) as record:
        run_blender(np.zeros(3), np.zeros(3), dt=0.5, e_max=3.0, lam_min=0.5, lam_max=0.6)
    messages = [str(w.message) for w in record]
    assert any(re.search(r"dt \* kappa_minus = 1.25 > 1", m) for m in messages), messages
    assert any(re.search(r"at the limit λ oscillates around λ\* = ", m) for m in messages), messages


def test_unstable_equilibrium_at_the_limit_is_refused():
    # dt κ < 2 on both pieces, but λ∞ is so steep at λ* that λ oscillates for ever there
    params = dict(lam_min=0.1, lam_max=1.4, e_max=0.2, kappa_plus=3.0, kappa_minus=5.0)
    with pytest.raises(DiagramError, match=r"bl: the equilibrium at the limit λ\* = .* is unstable"):
        run_blender(np.zeros(3), np.zeros(3), dt=0.1, **params)


def test_the_deprecated_dict_gives_the_deliverables_values_and_names_the_parameter_object():
    with pytest.warns(DeprecationWarning, match="DELIVERABLE_BLENDER is deprecated: use cogblocks.sync.DELIVERABLE"):
        from cogblocks.sync import DELIVERABLE_BLENDER
    # section 5.2.3.2: λ_min = e_max = 0.3·π/2, λ_max = π/2, κ⁺ = 1, κ⁻ = 2.5
    assert DELIVERABLE_BLENDER == pytest.approx(
        {
            "lam_min": 0.3 * math.pi / 2,
            "lam_max": math.pi / 2,
            "e_max": 0.3 * math.pi / 2,
            "kappa_plus": 1.0,
            "kappa_minus": 2.5,
        }
    )
