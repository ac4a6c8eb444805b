"""Kuramoto group, single oscillator and order parameter against a plain NumPy loop."""

import numpy as np
import pytest

from cogblocks.blocks import Mux, Playback, Probe
from cogblocks.sim import Diagram, Simulator
from cogblocks.sync import KuramotoGroup, KuramotoOscillator, OrderParameter, ring_adjacency

OMEGA = np.array([2.7151, 2.9299, 4.0344, 2.1476, 3.9117, 3.7429, 3.2827])
GAIN = 4.4 / 7


def numpy_kuramoto(omega, gain, a, n, theta_l2=None, assisted=None, dt=0.01):
    theta = np.zeros(len(omega))
    out = np.empty((n, len(omega)))
    for k in range(n):
        out[k] = theta
        seen = theta.copy()
        if assisted is not None:
            seen[assisted] = theta_l2[k]
        coupling = np.array(
            [sum(a[i, j] * np.sin(seen[j] - seen[i]) for j in range(len(omega))) for i in range(len(omega))]
        )
        theta = np.mod(theta + dt * (omega + gain * coupling), 2 * np.pi)
    return out


def test_ring_adjacency():
    a = ring_adjacency(5)
    assert a.sum(axis=1).tolist() == [2] * 5 and a[0, 4] == a[0, 1] == 1 and a[0, 2] == 0
    with pytest.raises(ValueError, match="ring_adjacency: n must be an integer >= 2, got 1"):
        ring_adjacency(1)


def test_group_matches_numpy_loop_and_order_parameter():
    d = Diagram()
    g = d.add("g", KuramotoGroup(OMEGA, GAIN))
    o = d.add("o", OrderParameter())
    d.connect(g.theta, o.theta)
    tr = Simulator(d, probes=["g.theta", "o.r"]).run(n_steps=3001)
    ref = numpy_kuramoto(OMEGA, GAIN, ring_adjacency(7), 3001)
    np.testing.assert_allclose(tr["g.theta"], ref, atol=1e-9)
    r = np.abs(np.exp(1j * ref).mean(axis=1))
    np.testing.assert_allclose(tr["o.r"], r, atol=1e-12)
    assert tr["o.r"][0] == pytest.approx(1.0)
    assert np.all((tr["g.theta"] >= 0) & (tr["g.theta"] < 2 * np.pi))


def test_table3_group3_without_l2_is_061():
    d = Diagram()
    g = d.add("g", KuramotoGroup(OMEGA, GAIN))
    o = d.add("o", OrderParameter())
    d.connect(g.theta, o.theta)
    r = Simulator(d, probes=["o.r"]).run(n_steps=30001)["o.r"]
    assert round(float(r.mean()), 2) == 0.61


def test_assisted_phase_replaces_own_in_coupling():
    theta_l2 = np.linspace(0, 6, 200) % (2 * np.pi)
    d = Diagram()
    src = d.add("src", Playback(theta_l2, unit="rad", wrapped=True))
    g = d.add("g", KuramotoGroup(OMEGA, GAIN, assisted=5))
    d.connect(src.y, g.theta_l2)
    tr = Simulator(d, probes=["g.theta"]).run(n_steps=200)
    ref = numpy_kuramoto(OMEGA, GAIN, ring_adjacency(7), 200, theta_l2=theta_l2, assisted=5)
    np.testing.assert_allclose(tr["g.theta"], ref, atol=1e-9)


def test_time_varying_frequencies_and_custom_graph():
    a = np.ones((3, 3)) - np.eye(3)
    omega_t = np.column_stack([np.linspace(1, 2, 50), np.full(50, 3.0), np.full(50, 0.5)])
    d = Diagram()
    src = d.add("src", Playback(omega_t, unit="rad/s"))
    g = d.add("g", KuramotoGroup([1.0, 3.0, 0.5], 1.0, adjacency=a))
    d.connect(src.y, g.omega)
    got = Simulator(d, probes=["g.theta"]).run(n_steps=50)["g.theta"]
    theta = np.zeros(3)
    for k in range(50):
        np.testing.assert_allclose(got[k], theta, atol=1e-12)
        theta = np.mod(theta + 0.01 * (omega_t[k] + (a * np.sin(theta[None, :] - theta[:, None])).sum(1)), 2 * np.pi)


def test_per_oscillator_diagram_equals_group_block():
    d = Diagram()
    osc = [d.add(f"o{i}", KuramotoOscillator(OMEGA[i], GAIN, 2)) for i in range(7)]
    m = d.add("mux", Mux(7))
    for i in range(7):
        d.connect(osc[(i - 1) % 7].theta, osc[i].theta_0)
        d.connect(osc[(i + 1) % 7].theta, osc[i].theta_1)
        d.connect(osc[i].theta, getattr(m, f"u{i}"))
    d.add("p", Probe())
    d.connect(m.y, "p.u")
    got = Simulator(d).run(n_steps=500)["p"]
    np.testing.assert_allclose(got, numpy_kuramoto(OMEGA, GAIN, ring_adjacency(7), 500), atol=1e-9)


def test_order_parameter_ignores_non_finite_phases():
    phases = np.array([[0.0, 0.0, np.nan], [np.nan, np.nan, np.nan], [0.0, np.pi, 0.0]])
    d = Diagram()
    src = d.add("src", Playback(phases, unit="rad", wrapped=True))
    o = d.add("o", OrderParameter())
    d.connect(src.y, o.theta)
    r = Simulator(d, probes=["o.r"]).run(n_steps=3)["o.r"]
    np.testing.assert_allclose(r, [1.0, 1.0, 1 / 3])


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(omega=[1.0], gain=1.0), "omega must hold at least 2 frequencies, got 1"),
        (dict(omega=[1.0, np.inf], gain=1.0), "omega must contain only finite numbers"),
        (dict(omega=[1.0, 2.0], gain=-1.0), r"gain must be a finite number in \[0.0, inf\), got -1.0"),
        (dict(omega=[1.0, 2.0], gain=1.0, adjacency=np.ones((3, 3))), r"adjacency must have shape \(2, 2\)"),
        (
            dict(omega=[1.0, 2.0], gain=1.0, adjacency="star"),
            r"adjacency must be 'ring', 'all', \('random', p, seed\) or an 2x2 matrix, got 'star'",
        ),
        (dict(omega=[1.0, 2.0], gain=1.0, assisted=2), r"assisted must be a 0-based index in \[0, 1\] or None, got 2"),
    ],
)
def test_group_parameter_errors(kwargs, message):
    with pytest.raises(ValueError, match="KuramotoGroup: " + message):
        KuramotoGroup(**kwargs)


def test_wrapping_never_returns_two_pi():
    from cogblocks.blocks.angles import wrap_2pi, wrap_angle

    assert wrap_angle(-1e-17) == 0.0 and wrap_2pi(-1e-17) == 0.0
    out = wrap_2pi(np.array([-1e-17, -0.5, 7.0]))
    assert np.all((out >= 0) & (out < 2 * np.pi)) and out[0] == 0.0
