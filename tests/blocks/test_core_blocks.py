"""The general-purpose blocks against independent computations."""

import control
import numpy as np
import pytest
import scipy.signal

from cogblocks.blocks import (
    Constant,
    Demux,
    DiscreteLTI,
    Function,
    Gain,
    Integrator,
    LowPass,
    Mux,
    Playback,
    Probe,
    Saturation,
    Sum,
    UnitDelay,
)
from cogblocks.sim import Diagram, DiagramError, Signal, SimulationError, Simulator


def run_chain(source_data, *blocks, n=None, dt=0.01, **playback):
    """Playback -> blocks in series -> probe; returns the probed array."""
    d = Diagram()
    prev = d.add("src", Playback(source_data, **playback)).y
    for i, b in enumerate(blocks):
        d.add(f"b{i}", b)
        d.connect(prev, b.u)
        prev = b.y
    d.add("p", Probe())
    d.connect(prev, "p.u")
    return Simulator(d, dt=dt).run(n_steps=n or len(source_data))["p"]


def test_constant_gain_sum():
    d = Diagram()
    a = d.add("a", Constant([1.0, 2.0], unit="mm"))
    b = d.add("b", Constant([10.0, 20.0], unit="mm"))
    s = d.add("s", Sum("-+"))
    g = d.add("g", Gain([2.0, -1.0]))
    m = d.add("m", Gain([[1.0, 1.0]], matrix=True))
    d.connect(a.y, s.u0)
    d.connect(b.y, s.u1)
    d.connect(s.y, g.u)
    d.connect(g.y, m.u)
    d.add("pg", Probe())
    d.add("pm", Probe())
    d.connect(g.y, "pg.u")
    d.connect(m.y, "pm.u")
    tr = Simulator(d).run(n_steps=2)
    np.testing.assert_array_equal(tr["pg"], [[18.0, -18.0]] * 2)
    np.testing.assert_array_equal(tr["pm"], [[0.0]] * 2)
    assert tr.units["pg"] == "mm"


def test_gain_shape_errors():
    with pytest.raises(ValueError, match="Gain: k must have 2 dimension"):
        Gain([1.0, 2.0], matrix=True)
    with pytest.raises(ValueError, match="Gain: k must contain only finite numbers"):
        Gain(np.nan)
    d = Diagram()
    d.add("c", Constant([1.0, 2.0, 3.0]))
    d.add("g", Gain([[1.0, 1.0]], matrix=True))
    d.connect("c.y", "g.u")
    with pytest.raises(DiagramError, match=r"g: a \(1, 2\) matrix gain needs an input of shape \(2,\)"):
        d.compile()
    with pytest.raises(ValueError, match="Sum: signs must be a non-empty string"):
        Sum("+*")


def test_unit_delay_and_integrator_against_numpy():
    u = np.random.default_rng(0).normal(size=(40, 2))
    np.testing.assert_array_equal(run_chain(u, UnitDelay([5.0, 6.0])), np.vstack([[5.0, 6.0], u[:-1]]))
    expected = np.vstack([[1.0, 1.0], 1.0 + np.cumsum(u * 0.01, axis=0)[:-1]])
    np.testing.assert_allclose(run_chain(u, Integrator(1.0)), expected, atol=1e-14)
    with pytest.raises(DiagramError, match="initial value of shape \\(3,\\) does not fit the signal shape \\(2,\\)"):
        run_chain(u, UnitDelay([1.0, 2.0, 3.0]))


def test_saturation():
    u = np.linspace(-3, 3, 13)
    np.testing.assert_array_equal(run_chain(u, Saturation(-1.0, 2.0)), np.clip(u, -1.0, 2.0))
    with pytest.raises(ValueError, match=r"Saturation: upper must be a finite number in \[2.0, inf\), got 1.0"):
        Saturation(2.0, 1.0)


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


def test_function_block():
    d = Diagram()
    a = d.add("a", Playback(np.arange(5.0)))
    f = d.add(
        "f",
        Function(
            lambda x, t: (x * 2, x + t),
            inputs={"x": Signal()},
            outputs={"double": Signal(), "plus_t": Signal(unit="s")},
        ),
    )
    d.connect(a.y, f.x)
    tr = Simulator(d, probes=["f.double", "f.plus_t"]).run(n_steps=5)
    np.testing.assert_array_equal(tr["f.double"], [0, 2, 4, 6, 8])
    np.testing.assert_allclose(tr["f.plus_t"], np.arange(5) * 1.01)
    d2 = Diagram()
    d2.add("f", Function(lambda: [1.0, 2.0], inputs={}, outputs=Signal(shape=(3,))))
    with pytest.raises(SimulationError, match=r"f: the function returned \(2,\) for output 'y' of shape \(3,\)"):
        Simulator(d2).run(n_steps=1)
    with pytest.raises(ValueError, match="Function: fn must be callable"):
        Function(3, inputs={}, outputs=Signal())


def test_playback_end_policies():
    data = np.array([1.0, 2.0, 3.0])
    assert run_chain(data, n=5).tolist() == [1, 2, 3, 3, 3]
    assert run_chain(data, n=5, at_end="repeat").tolist() == [1, 2, 3, 1, 2]
    assert run_chain(data, n=5, at_end="zero").tolist() == [1, 2, 3, 0, 0]
    with pytest.raises(SimulationError, match="played all 3 samples"):
        run_chain(data, n=5, at_end="error")
    with pytest.raises(ValueError, match="Playback: data must be an array with at least one row"):
        Playback([])
    with pytest.raises(ValueError, match="Playback: at_end must be one of"):
        Playback(data, at_end="loop")


def test_mux_demux_round_trip():
    d = Diagram()
    src = d.add("src", Playback(np.arange(12.0).reshape(4, 3), unit="mm"))
    dm = d.add("dm", Demux(3))
    mx = d.add("mx", Mux(3))
    d.connect(src.y, dm.u)
    for i in range(3):
        d.connect(getattr(dm, f"y{i}"), getattr(mx, f"u{i}"))
    d.add("p", Probe())
    d.connect(mx.y, "p.u")
    tr = Simulator(d).run(n_steps=4)
    np.testing.assert_array_equal(tr["p"], np.arange(12.0).reshape(4, 3))
    assert tr.units["p"] == "mm"


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


def test_select_and_substitute():
    from cogblocks.blocks import Select, Substitute

    d = Diagram()
    src = d.add("src", Playback(np.arange(12.0).reshape(3, 4), unit="rad", wrapped=True))
    sel = d.add("sel", Select(2))
    sub = d.add("sub", Substitute(1))
    d.connect(src.y, sel.u, sub.u)
    d.connect(sel.y, sub.v)
    tr = Simulator(d, probes=["sel.y", "sub.y"]).run(n_steps=3)
    np.testing.assert_array_equal(tr["sel.y"], [2.0, 6.0, 10.0])
    np.testing.assert_array_equal(tr["sub.y"], [[0, 2, 2, 3], [4, 6, 6, 7], [8, 10, 10, 11]])
    assert tr.units["sel.y"] == "rad"
    bad = Diagram()
    bad.add("src", Playback(np.zeros((2, 3))))
    bad.add("sel", Select(3))
    bad.connect("src.y", "sel.u")
    with pytest.raises(DiagramError, match=r"sel: index 3 does not fit an input of shape \(3,\)"):
        bad.compile()
    with pytest.raises(ValueError, match="Select: index must be an integer >= 0, got -1"):
        Select(-1)
    mixed = Diagram()
    mixed.add("src", Playback(np.zeros((2, 3)), unit="rad"))
    mixed.add("v", Playback(np.zeros(2), unit="mm"))
    mixed.add("sub", Substitute(0))
    mixed.connect("src.y", "sub.u")
    mixed.connect("v.y", "sub.v")
    with pytest.raises(DiagramError, match="sub: v .* does not match the elements of u .*unit 'mm' != 'rad'"):
        mixed.compile()
