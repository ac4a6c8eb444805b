"""The blender's law (eqs. 3–6), written once: the same numbers on floats, arrays and casadi, and the continuous law."""

import math
import warnings

import casadi as ca
import numpy as np
import pytest

from cogblocks.sim import Simulator
from cogblocks.sync import Blender
from cogblocks.sync.blending import (
    CONTINUOUS,
    DELIVERABLE,
    BlenderParams,
    alteration,
    blender_params,
    lam_inf,
    lam_step,
)

RNG = np.random.default_rng(3)
E = RNG.uniform(-2.0, 2.0, 200)
LAM = RNG.uniform(DELIVERABLE.lam_min, DELIVERABLE.lam_max, 200)


def _by_hand(lam: float, e: float, p: BlenderParams, dt: float) -> float:
    """Eqs. (5)-(6) as the deliverable writes them."""
    psi = max(0.0, 1.0 - abs(e) / p.e_max)
    target = psi * (p.lam_max - p.lam_min) + p.lam_min
    kappa = p.kappa_plus if lam <= target else p.kappa_minus
    return lam - dt * kappa * (lam - target)


def test_lam_step_is_the_same_on_floats_arrays_and_casadi():
    x, e = ca.SX.sym("lam"), ca.SX.sym("e")
    symbolic = ca.Function("step", [x, e], [lam_step(x, e, DELIVERABLE, 0.01)])
    expected = np.array([_by_hand(lam, e, DELIVERABLE, 0.01) for lam, e in zip(LAM, E, strict=True)])
    floats = np.array([lam_step(float(lam), float(e), DELIVERABLE, 0.01) for lam, e in zip(LAM, E, strict=True)])
    np.testing.assert_allclose(floats, expected, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(lam_step(LAM, E, DELIVERABLE, 0.01), floats)
    np.testing.assert_array_equal(np.asarray(symbolic(LAM, E)).ravel(), floats)


def test_the_bump_psi_agrees_between_floats_arrays_and_casadi():
    p = BlenderParams(psi="bump")
    e = ca.SX.sym("e")
    symbolic = np.asarray(ca.Function("inf", [e], [lam_inf(e, p)])(E)).ravel()
    floats = np.array([lam_inf(float(v), p) for v in E])
    np.testing.assert_allclose(lam_inf(E, p), floats, rtol=0, atol=1e-15)
    np.testing.assert_allclose(symbolic, floats, rtol=0, atol=1e-12)
    assert lam_inf(0.0, p) == p.lam_max and lam_inf(p.e_max, p) == p.lam_min


def test_the_deliverable_law_is_the_clip_of_the_wrapped_difference():
    d = RNG.uniform(-math.pi, math.pi, 200)
    np.testing.assert_array_equal(alteration(d, LAM, DELIVERABLE), np.clip(d, -LAM, LAM))
    assert alteration(3.0, 0.5, DELIVERABLE, previous=-0.5, dt=0.01) == 0.5  # no memory


def test_the_continuous_law_keeps_its_side_across_pi_and_moves_at_most_slew_dt():
    lam, dt, a = math.pi / 2, 0.01, 0.0
    steps, alterations = [], []
    # the reference runs away from θ_L0 at 2 rad/s: the wrapped difference crosses +π after about 1.3 s
    for k in range(500):
        d = math.pi - (math.pi - 0.5 - 2.0 * k * dt) % (2 * math.pi)
        new = alteration(d, lam, CONTINUOUS, a, dt)
        steps.append(abs(new - a))
        alterations.append(new)
        a = new
    assert max(steps) <= CONTINUOUS.slew * dt + 1e-12
    crossing = int(np.argmax(np.array([0.5 + 2.0 * k * dt for k in range(500)]) > math.pi))
    assert all(v == lam for v in alterations[crossing - 10 : crossing + 10])  # no flip to −λ at ±π
    # the deliverable's law flips there in one tick
    flip = [
        alteration(math.pi - (math.pi - x) % (2 * math.pi), lam, DELIVERABLE) for x in (math.pi - 0.01, math.pi + 0.01)
    ]
    assert flip == [lam, -lam]


def test_the_continuous_law_stays_within_lambda():
    a, lam = 1.5, 0.5  # λ fell below the last alteration: the output is inside ±λ at once
    assert alteration(1.5, lam, CONTINUOUS, a, 0.01) == lam


def test_old_spellings_warn_and_name_the_new_one():
    with pytest.warns(DeprecationWarning, match="lambda_min is now lam_min"):
        p = BlenderParams(lambda_min=0.1)
    assert p.lam_min == 0.1
    with pytest.warns(DeprecationWarning, match="kappa_down is now kappa_minus"):
        assert DELIVERABLE.kappa_down == 2.5
    with pytest.raises(ValueError, match="not both"), pytest.warns(DeprecationWarning):
        BlenderParams(lam_min=0.1, lambda_min=0.1)
    with pytest.raises(ValueError, match="unknown parameter"):
        BlenderParams(lam_mim=0.1)
    with pytest.raises(ValueError, match="slew must be None or a finite rate > 0"):
        BlenderParams(slew=0.0)


def test_blender_params_from_names_blocks_and_objects():
    assert blender_params("x", None) == DELIVERABLE and blender_params("x", "continuous") == CONTINUOUS
    block = Blender(lam_min=0.1, lam_max=0.6, e_max=0.2)
    assert blender_params("x", block) == BlenderParams(lam_min=0.1, lam_max=0.6, e_max=0.2)
    assert Blender(params=CONTINUOUS).params == CONTINUOUS
    with pytest.raises(ValueError, match="x: blender must be one of"):
        blender_params("x", "smooth")
    with pytest.raises(ValueError, match="give params or"):
        Blender(0.2, params=CONTINUOUS)


def test_the_continuous_blender_block_follows_the_law_tick_by_tick():
    from cogblocks.blocks import Constant, Playback
    from cogblocks.sim import Diagram

    t = np.arange(400) * 0.01
    ref = np.mod(0.5 + 2.0 * t, 2 * np.pi)
    d = Diagram()
    d.add("l0", Constant(0.0, unit="rad", wrapped=True))
    d.add("ref", Playback(ref, unit="rad", wrapped=True))
    blend = d.add("blend", Blender(params=CONTINUOUS))
    d.connect("l0.y", blend.theta_l0)
    d.connect("ref.y", blend.theta_ref)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        trace = Simulator(d, probes=["blend.theta_l2", "blend.lam"]).run(n_steps=len(t))
    shift = np.angle(np.exp(1j * trace["blend.theta_l2"]))
    lam, a = CONTINUOUS.lam_max, 0.0
    for k in range(len(t)):
        a = alteration(math.pi - (math.pi - ref[k]) % (2 * math.pi), lam, CONTINUOUS, a, 0.01)
        assert shift[k] == pytest.approx(a, abs=1e-12) and trace["blend.lam"][k] == pytest.approx(lam, abs=1e-15)
        lam = lam_step(lam, a, CONTINUOUS, 0.01)
    assert np.abs(np.diff(shift)).max() <= CONTINUOUS.slew * 0.01 + 1e-12
