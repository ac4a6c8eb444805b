"""UnitDelay, Integrator, LowPass and DiscreteLTI (cogblocks.blocks.discrete) against NumPy, SciPy, python-control."""

import control
import numpy as np
import pytest
import scipy.signal

from cogblocks.blocks import DiscreteLTI, Integrator, LowPass, UnitDelay
from cogblocks.sim import DiagramError
from tests.blocks.chain_helpers import run_chain


def test_unit_delay_and_integrator_against_numpy():
    u = np.random.default_rng(0).normal(size=(40, 2))
    np.testing.assert_array_equal(run_chain(u, UnitDelay([5.0, 6.0])), np.vstack([[5.0, 6.0], u[:-1]]))
    expected = np.vstack([[1.0, 1.0], 1.0 + np.cumsum(u * 0.01, axis=0)[:-1]])
    np.testing.assert_allclose(run_chain(u, Integrator(1.0)), expected, atol=1e-14)
    with pytest.raises(DiagramError, match="initial value of shape \\(3,\\) does not fit the signal shape \\(2,\\)"):
        run_chain(u, UnitDelay([1.0, 2.0, 3.0]))


@pytest.mark.parametrize("order", [1, 2, 4])
def test_lowpass_matches_scipy_sosfilt(order):
    rng = np.random.default_rng(order)
    u = np.cumsum(rng.normal(size=(500, 3)), axis=0)
    got = run_chain(u, LowPass(7.0, order=order, init="zero"))
    sos = scipy.signal.butter(order, 7.0, fs=100.0, output="sos")
    np.testing.assert_allclose(got, scipy.signal.sosfilt(sos, u, axis=0), rtol=1e-12, atol=1e-9)
    got_first = run_chain(u, LowPass(7.0, order=order))
    zi = scipy.signal.sosfilt_zi(sos)[:, :, None] * u[0]
    ref_first, _ = scipy.signal.sosfilt(sos, u, axis=0, zi=zi)
    np.testing.assert_allclose(got_first, ref_first, rtol=1e-12, atol=1e-9)


def test_lowpass_repeating_through_gaps_filters_the_signal_with_its_gaps_filled():
    """``gaps="repeat"``: each non-finite element is replaced by that element's last finite value."""
    rng = np.random.default_rng(5)
    u = np.cumsum(rng.normal(size=(300, 2)), axis=0)
    bad = u.copy()
    bad[:3, 1] = np.nan  # before any finite value of that element: the whole sample waits
    bad[100:140, 0] = np.nan
    bad[120:125, 1] = np.nan
    filled = bad.copy()
    for j in range(2):
        for i in range(1, len(filled)):
            if not np.isfinite(filled[i, j]):
                filled[i, j] = filled[i - 1, j]
    got = run_chain(bad, LowPass(5.0, gaps="repeat"))
    sos = scipy.signal.butter(2, 5.0, fs=100.0, output="sos")
    zi = scipy.signal.sosfilt_zi(sos)[:, :, None] * filled[3]
    ref, _ = scipy.signal.sosfilt(sos, filled[3:], axis=0, zi=zi)
    np.testing.assert_allclose(got[3:], ref, rtol=1e-12, atol=1e-9)
    with pytest.raises(ValueError, match=r"LowPass: gaps must be one of \['hold', 'repeat'\]"):
        LowPass(5.0, gaps="skip")


def test_lowpass_skips_bad_samples_and_checks_nyquist():
    u = np.sin(np.arange(100) * 0.1)
    bad = u.copy()
    bad[50] = np.nan
    clean = run_chain(np.delete(u, 50), LowPass(5.0))
    got = run_chain(bad, LowPass(5.0))
    assert np.all(np.isfinite(got))
    assert got[50] == got[49]  # held
    np.testing.assert_allclose(np.delete(got, 50), clean, rtol=1e-12)  # the state did not advance
    with pytest.raises(DiagramError, match="cutoff 60.0 Hz must be below the Nyquist frequency 50 Hz"):
        run_chain(u, LowPass(60.0))
    with pytest.raises(ValueError, match="LowPass: init must be one of"):
        LowPass(5.0, init="warm")
    with pytest.raises(ValueError, match="LowPass: order must be an integer >= 1, got 0"):
        LowPass(5.0, order=0)


@pytest.mark.parametrize(
    "sys",
    [
        control.ss([[0.9, 0.1], [0.0, 0.8]], [[0.0], [1.0]], [[1.0, 0.0]], [[0.5]], 0.01),
        control.ss([[0.5]], [[1.0, 2.0]], [[1.0], [3.0]], np.zeros((2, 2)), 0.01),
        control.tf([0.2, 0.1], [1.0, -0.7], 0.01),
    ],
    ids=["siso-feedthrough", "mimo-strictly-proper", "transfer-function"],
)
def test_discrete_lti_matches_forced_response(sys):
    ss = control.ss(sys)
    n_in, n_out = ss.ninputs, ss.noutputs
    rng = np.random.default_rng(1)
    u = rng.normal(size=(200, n_in))
    x0 = np.arange(1, ss.nstates + 1) * 0.1
    block = DiscreteLTI(sys, x0=x0)
    got = run_chain(u[:, 0] if n_in == 1 else u, block)
    t = np.arange(200) * 0.01
    ref = control.forced_response(ss, T=t, U=u.T, X0=x0).outputs
    ref = np.atleast_2d(ref).T
    np.testing.assert_allclose(np.reshape(got, (200, n_out)), ref, rtol=1e-10, atol=1e-12)
    assert block.u.feedthrough == bool(np.any(ss.D))


def test_discrete_lti_errors():
    with pytest.raises(ValueError, match="DiscreteLTI: sys must be discrete-time"):
        DiscreteLTI(control.ss([[-1.0]], [[1.0]], [[1.0]], [[0.0]]))
    with pytest.raises(ValueError, match="DiscreteLTI: x0 must have shape \\(1\\)"):
        DiscreteLTI(control.ss([[0.5]], [[1.0]], [[1.0]], [[0.0]], 0.01), x0=[1.0, 2.0])
    with pytest.raises(DiagramError, match="the system's dt 0.1 s differs from the block's step 0.01 s"):
        run_chain(np.zeros(3), DiscreteLTI(control.ss([[0.5]], [[1.0]], [[1.0]], [[0.0]], 0.1)))
    with pytest.raises(ValueError, match="DiscreteLTI: sys must be a control.StateSpace"):
        DiscreteLTI([[1.0]])
