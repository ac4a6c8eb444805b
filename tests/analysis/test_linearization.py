"""Kuramoto linearisation and finite-difference linearisation of compiled diagrams."""

import math

import control
import numpy as np
import pytest
import scipy.signal

from cogblocks.analysis import kuramoto_jacobian, kuramoto_linearization, linearize
from cogblocks.blocks import DiscreteLTI, Gain, LowPass, Sum, UnitDelay
from cogblocks.data.groups import TABLE2
from cogblocks.sim import Block, Diagram, Signal
from cogblocks.sync import Blender, KuramotoGroup, ring_adjacency

ALL_TO_ALL = np.ones((3, 3)) - np.eye(3)
# ω = 3 ∓ (sin(π/3) + sin(π/6)): the all-to-all triangle locks at offsets (−π/6, 0, π/6)
SPREAD = math.sin(math.pi / 3) + math.sin(math.pi / 6)
TRIANGLE = 3.0 + np.array([-SPREAD, 0.0, SPREAD])


def euler_map(theta, omega, gain, a, dt):
    return theta + dt * (omega + gain * (a * np.sin(theta[None, :] - theta[:, None])).sum(axis=1))


def central_differences(f, x, h=1e-6):
    return np.column_stack([(f(x + h * e) - f(x - h * e)) / (2 * h) for e in np.eye(len(x))])


def test_kuramoto_jacobian_against_central_differences_of_the_one_step_map():
    rng = np.random.default_rng(3)
    omega, a, dt = rng.normal(3.0, 0.5, 5), ring_adjacency(5), 0.01
    theta = rng.uniform(0, 2 * np.pi, 5)
    numeric = central_differences(lambda th: euler_map(th, omega, 0.7, a, dt), theta)
    np.testing.assert_allclose(np.eye(5) + dt * kuramoto_jacobian(theta, 0.7, a), numeric, atol=1e-9)
    np.testing.assert_allclose(kuramoto_jacobian(theta, 0.7, a).sum(axis=1), 0.0, atol=1e-15)


def test_locked_all_to_all_triangle_against_hand_computation():
    lin = kuramoto_linearization(TRIANGLE, 1.0, adjacency=ALL_TO_ALL, dt=0.01)
    assert lin.locked and lin.frequency == pytest.approx(3.0)
    np.testing.assert_allclose(lin.phases, [0.0, math.pi / 6, math.pi / 3], atol=1e-10)
    # links 0–1 and 1–2 at π/6 (weight a = cos π/6), link 0–2 at π/3 (weight b = cos π/3):
    # J = −L has eigenvalues 0, −3a (mode (1, −2, 1)) and −(a + 2b) (mode (1, 0, −1))
    a, b = math.cos(math.pi / 6), math.cos(math.pi / 3)
    np.testing.assert_allclose(lin.eigenvalues, [0.0, -(a + 2 * b), -3 * a], atol=1e-10)
    assert lin.rate == pytest.approx(-(a + 2 * b))
    np.testing.assert_allclose(lin.continuous.A, lin.jacobian)
    np.testing.assert_allclose(lin.discrete.A, np.eye(3) + 0.01 * lin.jacobian)
    np.testing.assert_allclose(lin.discrete.B, 0.01 * np.eye(3))
    assert lin.discrete.dt == 0.01 and lin.continuous.isctime()
    assert lin.discrete.state_labels == ["theta[0]", "theta[1]", "theta[2]"]
    assert lin.discrete.input_labels == ["omega[0]", "omega[1]", "omega[2]"]
    numeric = central_differences(lambda th: euler_map(th, TRIANGLE, 1.0, ALL_TO_ALL, 0.01), lin.phases)
    np.testing.assert_allclose(lin.discrete.A, numeric, atol=1e-9)


def test_table2_groups_do_not_lock():
    for gid in (1, 2):
        lin = kuramoto_linearization(TABLE2[gid].omega, TABLE2[gid].gain)
        assert not lin.locked and lin.phases is None
        assert "no phase-locked state exists" in lin.message and "locking needs gain" in lin.message
    # Group 1: participant #4 (index 3) is 4.34 rad/s from the mean, its two links pull 2 × 1.6 at most
    lin = kuramoto_linearization(TABLE2[1].omega, TABLE2[1].gain)
    assert "[3]" in lin.message and "2.169" in lin.message
    # Group 3 passes the cut test, but its only locked states are unstable: it drifts
    g3 = TABLE2[3]
    lin = kuramoto_linearization(g3.omega, g3.gain)
    assert not lin.locked and lin.phases is not None and not lin.stable
    assert lin.rate > 0 and "no stable phase-locked state" in lin.message
    # a little more coupling and it locks, at Ω = mean(ω)
    locked = kuramoto_linearization(g3.omega, 0.7)
    assert locked.locked and locked.rate < 0
    assert locked.frequency == pytest.approx(np.mean(g3.omega))


def test_ring_lock_against_simulation_of_the_group():
    omega, gain = [2.0, 2.3, 1.8, 2.6, 2.1], 0.8
    lin = kuramoto_linearization(omega, gain)
    assert lin.locked
    d = Diagram()
    group = d.add("group", KuramotoGroup(omega, gain))
    d.expose_output("theta", group.theta)
    compiled = d.compile(0.01)
    for _ in range(3000):
        theta = compiled.step()["theta"]
    offsets = np.angle(np.exp(1j * (theta - theta[0])))
    np.testing.assert_allclose(offsets, lin.phases, atol=1e-6)


def kuramoto_diagram(omega, gain, adjacency, theta0, expose_omega=False):
    d = Diagram()
    group = d.add("group", KuramotoGroup(omega, gain, adjacency=adjacency, theta0=theta0))
    d.expose_output("theta", group.theta)
    if expose_omega:
        d.expose_input("omega", group.omega)
    d.compile(0.01)
    return d


def test_linearize_a_diagram_holding_a_kuramoto_group():
    lin = kuramoto_linearization(TRIANGLE, 1.0, adjacency=ALL_TO_ALL)
    # rotated so that θ_0 reaches 2π in exactly one tick: its next value wraps either way
    d = kuramoto_diagram(TRIANGLE, 1.0, ALL_TO_ALL, lin.phases - 0.01 * lin.frequency, expose_omega=True)
    sys = linearize(d, inputs={"omega": TRIANGLE})
    np.testing.assert_allclose(sys.A, lin.discrete.A, atol=1e-8)
    np.testing.assert_allclose(sys.B, lin.discrete.B, atol=1e-8)
    np.testing.assert_allclose(sys.C, np.eye(3), atol=1e-8)
    np.testing.assert_allclose(sys.D, 0.0, atol=1e-8)
    assert sys.dt == 0.01
    assert sys.state_labels == ["group.phase[0]", "group.phase[1]", "group.phase[2]"]
    assert sys.input_labels == ["omega[0]", "omega[1]", "omega[2]"]
    assert sys.output_labels == ["theta[0]", "theta[1]", "theta[2]"]
    # the phase state was recognised as an angle: without wrapping its differences, θ_0's row is nonsense
    unwrapped = linearize(d, inputs={"omega": TRIANGLE}, wrapped_states=[])
    assert np.abs(unwrapped.A[0]).max() > 1e3
    np.testing.assert_allclose(linearize(d, inputs={"omega": TRIANGLE}, wrapped_states=["group.phase"]).A, sys.A)


def test_linearize_leaves_the_state_as_it_found_it():
    d = kuramoto_diagram(TRIANGLE, 1.0, ALL_TO_ALL, [0.1, 0.5, 6.2])
    compiled = d.compiled
    for _ in range(7):
        compiled.step()
    before = compiled.state_dict()
    point = compiled.state_dict()
    point["blocks"]["group"]["state"]["phase"] = np.array([1.0, 2.0, 3.0])
    sys = linearize(compiled, point)
    np.testing.assert_allclose(sys.A, np.eye(3) + 0.01 * kuramoto_jacobian([1.0, 2.0, 3.0], 1.0, ALL_TO_ALL), atol=1e-8)
    after = compiled.state_dict()
    assert after["k"] == before["k"] == 7
    np.testing.assert_array_equal(
        after["blocks"]["group"]["state"]["phase"], before["blocks"]["group"]["state"]["phase"]
    )
    np.testing.assert_array_equal(
        after["blocks"]["group"]["outputs"]["theta"], before["blocks"]["group"]["outputs"]["theta"]
    )


@pytest.mark.parametrize("n, m, p", [(3, 2, 2), (2, 1, 1)])
def test_linearize_a_discrete_lti_block_gives_back_its_matrices(n, m, p):
    rng = np.random.default_rng(n)
    a, b, c, d = (
        rng.normal(size=(n, n)) * 0.4,
        rng.normal(size=(n, m)),
        rng.normal(size=(p, n)),
        rng.normal(size=(p, m)),
    )
    diagram = Diagram()
    lti = diagram.add("lti", DiscreteLTI(control.ss(a, b, c, d, 0.01), x0=rng.normal(size=n)))
    diagram.expose_input("u", lti.u)
    diagram.expose_output("y", lti.y)
    compiled = diagram.compile(0.01)
    compiled.step(u=rng.normal(size=m) if m > 1 else 0.3)
    before = compiled.state_dict()
    sys = linearize(compiled, inputs={"u": rng.normal(size=m) if m > 1 else -2.0})
    np.testing.assert_array_equal(compiled.state_dict()["inputs"]["u"], before["inputs"]["u"])
    for got, expected in zip((sys.A, sys.B, sys.C, sys.D), (a, b, c, d), strict=True):
        np.testing.assert_allclose(got, expected, atol=1e-8)
    assert sys.state_labels == [f"lti.x[{i}]" for i in range(n)]
    assert sys.input_labels == (["u"] if m == 1 else [f"u[{i}]" for i in range(m)])


def test_linearize_a_gain_sum_delay_loop_against_the_hand_derived_model():
    # x1+ = r + 0.5 x1 − 0.2 x2, x2+ = x1;  y = (r + 0.5 x1 − 0.2 x2, x2)
    d = Diagram()
    s = d.add("s", Sum("++-"))
    d1 = d.add("d1", UnitDelay(0.3))
    d2 = d.add("d2", UnitDelay(-0.1))
    g1 = d.add("g1", Gain(0.5))
    g2 = d.add("g2", Gain(0.2))
    d.connect(s.y, d1.u)
    d.connect(d1.y, d2.u, g1.u)
    d.connect(d2.y, g2.u)
    d.connect(g1.y, s.u1)
    d.connect(g2.y, s.u2)
    d.expose_input("r", s.u0, spec=Signal())
    d.expose_output("sum", s.y)
    d.expose_output("x2", d2.y)
    d.compile(0.01)
    sys = linearize(d, inputs={"r": 1.5})
    np.testing.assert_allclose(sys.A, [[0.5, -0.2], [1.0, 0.0]], atol=1e-9)
    np.testing.assert_allclose(sys.B, [[1.0], [0.0]], atol=1e-9)
    np.testing.assert_allclose(sys.C, [[0.5, -0.2], [0.0, 1.0]], atol=1e-9)
    np.testing.assert_allclose(sys.D, [[1.0], [0.0]], atol=1e-9)
    assert list(d.compiled.blocks) == ["d1", "g1", "d2", "g2", "s"]  # execution order: x = (d1.x, d2.x)
    assert sys.state_labels == ["d1.x", "d2.x"] and sys.output_labels == ["sum", "x2"]


def test_linearize_the_blender_with_wrapped_inputs():
    # small offset: θ_L2 = θ_ref, and λ decays toward λ∞(e) at κ⁻ with e = θ_ref − θ_L0
    d = Diagram()
    bl = d.add("bl", Blender())
    d.expose_input("l0", bl.theta_l0)
    d.expose_input("ref", bl.theta_ref)
    d.expose_output("l2", bl.theta_l2)
    d.expose_output("lam", bl.lam)
    d.compile(0.01)
    sys = linearize(d, inputs={"l0": 0.0, "ref": 0.1})
    assert sys.state_labels == ["bl.lam_now", "bl.shift_now"] and sys.input_labels == ["l0", "ref"]
    slope = -(bl.lam_max - bl.lam_min) / bl.e_max
    # shift_now, the last alteration θ_ref − θ_L0, is memory only: it follows the inputs and feeds nothing
    np.testing.assert_allclose(sys.A, [[1 - 0.01 * bl.kappa_minus, 0.0], [0.0, 0.0]], atol=1e-9)
    k = 0.01 * bl.kappa_minus
    np.testing.assert_allclose(sys.B, [[k * -slope, k * slope], [-1.0, 1.0]], atol=1e-8)
    np.testing.assert_allclose(sys.C, [[0.0, 0.0], [1.0, 0.0]], atol=1e-9)
    np.testing.assert_allclose(sys.D, [[0.0, 1.0], [0.0, 0.0]], atol=1e-9)


class NoisyLeak(Block):
    """x+ = a x + u + noise, y = x: a block with a random generator state."""

    def __init__(self, a):
        super().__init__()
        self.a = a
        self.add_input("u", unit="1", feedthrough=False)
        self.add_output("y", unit="1")
        self.add_state("x", 0.5)
        self.add_state("rng", np.random.default_rng(7))

    def output(self, k):
        self.y.value[...] = self.x

    def update(self, k):
        self.x = self.a * self.x + float(self.u.value) + 0.1 * self.rng.normal()


def test_random_generator_states_are_refused_unless_held():
    d = Diagram()
    leak = d.add("leak", NoisyLeak(0.9))
    d.expose_input("u", leak.u)
    d.expose_output("y", leak.y)
    compiled = d.compile(0.01)
    with pytest.raises(ValueError, match=r"block 'leak' has state 'rng' of type Generator.*hold=\['leak.rng'\]"):
        linearize(compiled, inputs={"u": 0.0})
    with pytest.raises(ValueError, match="names no state"):
        linearize(compiled, inputs={"u": 0.0}, hold=["leak.seed"])
    # held: every evaluation sees the same draw, the generator is left where it was
    sys = linearize(compiled, inputs={"u": 0.0}, hold=["leak.rng"])
    np.testing.assert_allclose([sys.A[0, 0], sys.B[0, 0], sys.C[0, 0]], [0.9, 1.0, 1.0], atol=1e-9)
    first = [compiled.step(u=0.0)["y"] for _ in range(3)]
    reference = d.compile(0.01)
    assert first == [reference.step(u=0.0)["y"] for _ in range(3)]


def test_boolean_state_of_a_low_pass_held_gives_the_filter_transfer_function():
    d = Diagram()
    lp = d.add("lp", LowPass(5.0, init="zero"))
    d.expose_input("u", lp.u, spec=Signal())
    d.expose_output("y", lp.y)
    compiled = d.compile(0.01)
    with pytest.raises(ValueError, match="block 'lp' has state 'primed' of type bool"):
        linearize(compiled, inputs={"u": 0.0})
    sys = linearize(compiled, inputs={"u": 0.0}, hold=["lp.primed"])
    b, a = scipy.signal.sos2tf(lp.sos)
    z = np.exp(1j * np.array([0.1, 0.7, 2.0]))
    expected = np.polyval(b, z) / np.polyval(a, z)
    np.testing.assert_allclose([complex(sys(zi)) for zi in z], expected, atol=1e-8)


def test_multirate_diagrams_are_refused():
    d = Diagram()
    delay = d.add("delay", UnitDelay(0.0, shape=(), unit="1"), period=0.05)
    d.expose_input("u", delay.u, spec=Signal())
    d.expose_output("y", delay.y)
    d.compile(0.01)
    with pytest.raises(ValueError, match=r"\['delay'\] run slower"):
        linearize(d, inputs={"u": 0.0})
