"""What a new user hits in the engine (issue 13): ownership of plans, snapshots, messages, threads, drawing,
linear algebraic loops, gain units, the duration convention."""

import decimal
import re
import shutil
import threading
from decimal import Decimal
from pathlib import Path

import control
import numpy as np
import pytest
import torch

from cogblocks.blocks import (
    Constant,
    DiscreteLTI,
    Gain,
    Integrator,
    Playback,
    Probe,
    Saturation,
    Sum,
    UnitDelay,
)
from cogblocks.diagrams.sync import pop_sync
from cogblocks.sim import Block, Diagram, DiagramError, Signal, SimulationError, Simulator


def _counter_loop() -> Diagram:
    """x[k+1] = x[k] + dt * 1, probed."""
    d = Diagram()
    c = d.add("c", Constant(1.0))
    x = d.add("x", Integrator(unit="1"))
    d.connect(c.y, x.u)
    d.add("p", Probe())
    d.connect(x.y, "p.u")
    return d


# -- 1. plans of one diagram are independent ------------------------------------------------------


def test_two_simulators_of_one_diagram_are_independent():
    d = pop_sync(3, motion="mean", blender="deliverable")
    a, b = Simulator(d), Simulator(d)
    first = a.run(n_steps=200)["r"]
    second = b.run(n_steps=200)["r"]
    fresh = Simulator(pop_sync(3, motion="mean", blender="deliverable")).run(n_steps=300)["r"]
    np.testing.assert_array_equal(first, fresh[:200])
    np.testing.assert_array_equal(second, fresh[:200])
    # interleaved runs continue each plan from its own state
    np.testing.assert_array_equal(a.run(n_steps=100)["r"], fresh[200:])
    assert a.compiled.k == 300 and b.compiled.k == 200


def test_the_latest_plan_runs_the_diagram_blocks_earlier_plans_continue_on_copies():
    d = _counter_loop()
    x = d["x"]
    a = Simulator(d)
    a.run(n_steps=10)
    b = Simulator(d, dt=0.5)
    assert b.compiled.blocks["x"] is x and a.compiled.blocks["x"] is not x
    assert float(a.compiled.blocks["x"].x) == pytest.approx(10 * 0.01)  # a kept its state
    np.testing.assert_allclose(a.run(n_steps=3)["p"], [0.10, 0.11, 0.12])  # and continues from it
    b.run(n_steps=3)
    assert float(x.x) == pytest.approx(3 * 0.5)  # the block you hold shows the latest plan's run
    assert d.compiled is b.compiled  # the last compile, as d.step() uses
    d.step()
    assert b.compiled.k == 4 and a.compiled.k == 13 and float(x.x) == pytest.approx(4 * 0.5)


def test_copies_share_networks_and_read_only_tables_not_state():
    class Lookup(Block):
        """y = net(table[k]) for a test; Bad data policy: none (test block)."""

        def __init__(self):
            super().__init__()
            self.net = torch.nn.Linear(2, 1)
            self.table = np.arange(6.0).reshape(3, 2).copy()  # owns its data
            self.table.setflags(write=False)
            self.scratch = np.zeros(2)  # writeable: copied
            self.view = self.scratch[:1]
            self.view.setflags(write=False)  # read-only, but its base can change: copied
            self.add_output("y")
            self.add_state("count", np.zeros(()))

        def output(self, k):
            with torch.no_grad():
                self.y.value[...] = float(self.net(torch.tensor(self.table[k % 3], dtype=torch.float32)).item())

        def update(self, k):
            self.count += 1

    d = Diagram()
    block = d.add("look", Lookup())
    a = Simulator(d)
    a.run(n_steps=2)
    b = Simulator(d)
    copy = a.compiled.blocks["look"]
    assert b.compiled.blocks["look"] is block and float(copy.count) == 2
    assert copy.net is block.net and copy.table is block.table
    assert copy.scratch is not block.scratch and copy.count is not block.count
    assert copy.view is not block.view
    b.run(n_steps=4)
    assert float(block.count) == 4 and float(copy.count) == 2


def test_an_earlier_plan_whose_blocks_cannot_be_copied_ends_and_names_the_block():
    class Locked(Block):
        """Holds a lock. Bad data policy: none (test block)."""

        def __init__(self):
            super().__init__()
            self.guard = threading.Lock()
            self.add_output("y")

    d = Diagram()
    d.add("locked", Locked())
    first = Simulator(d)
    first.run(n_steps=2)
    second = Simulator(d)
    assert second.run(n_steps=3).t.tolist() == [0.0, 0.01, 0.02]
    with pytest.raises(SimulationError, match=r"took over its blocks, and block 'locked' \(Locked\) cannot be copied"):
        first.run(n_steps=1)


def test_replace_makes_earlier_plans_refuse_to_run():
    d = Diagram()
    c = d.add("c", Constant(1.0))
    g = d.add("g", Gain(2.0))
    d.connect(c.y, g.u)
    d.add("p", Probe())
    d.connect(g.y, "p.u")
    old = Simulator(d)
    assert old.run(n_steps=2)["p"].tolist() == [2.0, 2.0]
    d.replace("g", Gain(5.0))
    with pytest.raises(SimulationError, match="changed .* after this plan was compiled.*compile it again"):
        old.run(n_steps=1)
    with pytest.raises(SimulationError, match="compile it again"):
        old.compiled.step()
    assert Simulator(d).run(n_steps=2)["p"].tolist() == [5.0, 5.0]
    assert d.compiled.current and not old.compiled.current


def test_changing_a_sub_diagram_makes_the_outer_plans_stale():
    inner = Diagram()
    g = inner.add("g", Gain(2.0))
    inner.expose_input("u", g.u)
    inner.expose_output("y", g.y)
    d = Diagram()
    c = d.add("c", Constant(1.0))
    sub = d.add("sub", inner)
    d.connect(c.y, sub.u)
    plan = d.compile()
    inner.replace("g", Gain(3.0))
    assert not plan.current
    with pytest.raises(SimulationError, match="compile it again"):
        plan.advance(1)


# -- 2. snapshots are checked, atomic, and saved to files ---------------------------------------------


def test_load_state_dict_checks_everything_before_changing_anything():
    sim = Simulator(pop_sync(3, motion="mean", blender="deliverable"))
    sim.run(n_steps=50)
    snap = sim.state_dict()
    sim.run(n_steps=10)
    before = sim.state_dict()
    bad = sim.state_dict()
    bad["blocks"]["group"]["state"]["phase"] = np.zeros(2)  # the group has 3 phases... the wrong shape
    bad["k"] = snap["k"]
    with pytest.raises(ValueError, match=r"block 'group' \(KuramotoGroup\): state 'phase' expects an array of shape"):
        sim.load_state_dict(bad)
    wrong_dtype = sim.state_dict()
    wrong_dtype["blocks"]["order"]["outputs"]["r"] = np.zeros((), dtype=np.float32)
    with pytest.raises(ValueError, match=r"block 'order' .*output 'r' expects .*dtype float64"):
        sim.load_state_dict(wrong_dtype)
    after = sim.state_dict()
    assert after["k"] == before["k"]
    for path, block_state in before["blocks"].items():
        for part in ("state", "outputs"):
            for name, value in block_state[part].items():
                np.testing.assert_array_equal(after["blocks"][path][part][name], value, err_msg=f"{path}.{name}")


def test_a_snapshot_of_another_diagram_is_refused_as_a_whole():
    def one(block):
        d = Diagram()
        c = d.add("c", Constant(1.0))
        b = d.add("b", block)
        d.connect(c.y, b.u)
        return Simulator(d)

    delay, gain = one(UnitDelay()), one(Gain(1.0))
    delay.run(n_steps=3)
    with pytest.raises(ValueError, match=r"block 'b' \(Gain\): state dict has state \['x'\].*nothing was loaded"):
        gain.load_state_dict(delay.state_dict())
    with pytest.raises(
        ValueError,
        match=r"another diagram: only in the snapshot \['group', .*only in this diagram \['c', 'p', 'x'\]",
    ):
        Simulator(_counter_loop()).load_state_dict(
            Simulator(pop_sync(1, motion="mean", blender="deliverable")).state_dict()
        )


class _Noisy(Block):
    """A random walk with a generator, an integer and a float state. Bad data policy: none (test block)."""

    def __init__(self):
        super().__init__()
        self.add_output("y")
        self.add_state("rng", np.random.default_rng(7))
        self.add_state("steps", 0)
        self.add_state("level", 0.25)

    def output(self, k):
        self.y.value[...] = self.level

    def update(self, k):
        self.level = self.level + float(self.rng.normal())
        self.steps += 1


def test_snapshot_file_reloads_bit_exact(tmp_path):
    d = pop_sync(2, motion="mean", blender="deliverable")
    d.add("noise", _Noisy())
    d.add("pn", Probe())
    d.connect("noise.y", "pn.u")
    sim = Simulator(d)
    sim.run(n_steps=123)
    path = tmp_path / "snap.npz"
    sim.save_state(path)
    first = sim.run(n_steps=200)
    other = Simulator(d)  # a second, independent plan loads the file
    other.load_state(path)
    second = other.run(n_steps=200)
    for name in ("r", "pn"):
        np.testing.assert_array_equal(first[name], second[name])
    np.testing.assert_array_equal(first.t, second.t)
    assert type(other.compiled.blocks["noise"].steps) is int and other.compiled.blocks["noise"].steps == 323
    with np.load(path, allow_pickle=False) as f:  # no pickle inside
        assert "__manifest__" in f.files


def test_snapshot_file_of_a_compiled_plan_and_a_refused_file(tmp_path):
    plan = _counter_loop().compile()
    plan.advance(5)
    plan.save_state(tmp_path / "a.npz")
    plan.advance(5)
    plan.load_state(tmp_path / "a.npz")
    assert plan.k == 5 and float(plan.blocks["x"].x) == pytest.approx(0.05)
    np.savez(tmp_path / "other.npz", x=np.zeros(3))
    with pytest.raises(ValueError, match="not a cogblocks snapshot"):
        plan.load_state(tmp_path / "other.npz")


# -- 3. input names and shapes ----------------------------------------------------------------------


def _gain_with_input() -> Diagram:
    d = Diagram()
    g = d.add("g", Gain(2.0))
    d.expose_input("theta", g.u, spec=Signal(shape=(3,), unit="rad"))
    d.expose_output("y", g.y)
    return d


def test_step_with_an_unknown_input_names_it_and_lists_the_inputs():
    plan = _gain_with_input().compile()
    with pytest.raises(KeyError, match=r"no input 'thx' \(did you mean 'theta'\?\); its inputs are \['theta'\]"):
        plan.step(thx=np.zeros(3))
    with pytest.raises(KeyError, match=r"no input 'thx'"):
        Simulator(_gain_with_input()).run(n_steps=2, inputs={"thx": np.zeros(3)})


def test_run_inputs_of_the_wrong_shape_name_the_input_and_the_shape():
    sim = Simulator(_gain_with_input())
    with pytest.raises(ValueError, match=r"input 'theta': the function returned a value of shape \(\) .* shape \(3,\)"):
        sim.run(n_steps=2, inputs={"theta": lambda t: 1.0})
    with pytest.raises(ValueError, match=r"input 'theta': expected a constant of shape \(3,\) or an array of shape"):
        sim.run(n_steps=2, inputs={"theta": np.zeros((2, 2))})
    with pytest.raises(ValueError, match=r"input 'theta': expected float64 values of shape \(3,\)"):
        sim.run(n_steps=2, inputs={"theta": [[1, 2], [3]]})
    assert sim.compiled.k == 0
    out = sim.run(n_steps=2, inputs={"theta": lambda t: np.full(3, t)}, include_end=False)
    assert out.t.tolist() == [0.0, 0.01]


# -- 4. threads -------------------------------------------------------------------------------------------


def test_stepping_one_plan_from_two_threads_at_once_raises():
    entered, release = threading.Event(), threading.Event()

    class Slow(Block):
        """Waits inside its output. Bad data policy: none (test block)."""

        def __init__(self):
            super().__init__()
            self.add_output("y")

        def output(self, k):
            entered.set()
            release.wait(5.0)

    d = Diagram()
    d.add("slow", Slow())
    plan = d.compile()
    worker = threading.Thread(target=plan.step)
    worker.start()
    try:
        assert entered.wait(5.0)
        with pytest.raises(SimulationError, match="already running .* not thread-safe"):
            plan.step()
        with pytest.raises(SimulationError, match="already running"):
            plan.advance(3)
    finally:
        release.set()
        worker.join()
    assert plan.k == 1  # only the first thread's tick ran
    plan.advance(2)
    assert plan.k == 3


# -- 5. repr and drawing --------------------------------------------------------------------------------


def test_diagram_repr_lists_blocks_and_exposed_ports():
    d = _gain_with_input()
    text = repr(d)
    assert "blocks=[g: Gain]" in text and "inputs=(theta -> g.u)" in text and "outputs=(y <- g.y)" in text
    outer = Diagram()
    outer.add("inner", d)
    assert "inner: Diagram (1 blocks)" in repr(outer)


def test_draw_writes_text_formats_and_renders_pictures_with_graphviz(tmp_path):
    d = pop_sync(1, motion="mean", blender="deliverable")
    d.draw(tmp_path / "d.dot")
    d.draw(tmp_path / "d.mmd")
    assert (tmp_path / "d.dot").read_text().strip() == d.to_dot()
    assert (tmp_path / "d.mmd").read_text().strip() == d.to_mermaid()
    with pytest.raises(ValueError, match=r"unknown suffix '.jpeg'; use one of .dot, .gv, .mmd, .svg"):
        d.draw(tmp_path / "d.jpeg")
    if shutil.which("dot") is None:
        with pytest.raises(RuntimeError, match="needs Graphviz's 'dot' program, which is not installed"):
            d.draw(tmp_path / "d.svg")
        assert not (tmp_path / "d.svg").exists()
    else:
        d.draw(tmp_path / "d.svg")
        assert "<svg" in (tmp_path / "d.svg").read_text()


# -- 16. an exposed input without a spec ----------------------------------------------------------------


def test_exposed_input_without_spec_feeding_generic_blocks_asks_for_a_spec():
    d = Diagram()
    g = d.add("g", Gain(2.0))
    d.expose_input("u", g.u)
    d.add("p", Probe())
    d.connect(g.y, "p.u")
    with pytest.raises(
        DiagramError, match=r"the diagram input 'u' has no full spec .*expose_input\('u', \.\.\., spec="
    ):
        d.compile()


# -- 17. algebraic loops of linear blocks -------------------------------------------------------------------


def _feedback_diagram(controller, plant, reference):
    d = Diagram()
    r = d.add("r", Playback(reference))
    e = d.add("e", Sum("+-"))
    c = d.add("c", DiscreteLTI(controller))
    p = d.add("p", DiscreteLTI(plant))
    d.connect(r.y, e.u0)
    d.connect(e.y, c.u)
    d.connect(c.y, p.u)
    d.connect(p.y, e.u1)
    d.add("y", Probe())
    d.connect(p.y, "y.u")
    return d


def _closed_loop_40_digits(controller, plant, reference):
    """The loop's exact recursion in 40-digit decimals, from the same float matrices."""
    decimal.getcontext().prec = 40

    def dec(m):
        return [[Decimal(float(v)) for v in row] for row in np.atleast_2d(m)]

    def mul(a, b):
        return [
            [sum((a[i][k] * b[k][j] for k in range(len(b))), Decimal(0)) for j in range(len(b[0]))]
            for i in range(len(a))
        ]

    def add(a, b):
        return [[x + y for x, y in zip(ra, rb, strict=True)] for ra, rb in zip(a, b, strict=True)]

    ap, bp, cp, dp = (dec(m) for m in (plant.A, plant.B, plant.C, plant.D))
    ac, bc, cc, dc = (dec(m) for m in (controller.A, controller.B, controller.C, controller.D))
    xp = [[Decimal(0)] for _ in ap]
    xc = [[Decimal(0)] for _ in ac]
    out = []
    for r in map(Decimal, reference.tolist()):
        d_p, d_c = dp[0][0], dc[0][0]
        # y = Cp xp + Dp (Cc xc + Dc (r - y))  solved for y
        y = (mul(cp, xp)[0][0] + d_p * mul(cc, xc)[0][0] + d_p * d_c * r) / (1 + d_p * d_c)
        e = r - y
        u = mul(cc, xc)[0][0] + d_c * e
        out.append(float(y))
        xp = add(mul(ap, xp), mul(bp, [[u]]))
        xc = add(mul(ac, xc), mul(bc, [[e]]))
    return np.array(out)


def test_loop_of_a_controller_and_a_tustin_plant_matches_python_control_feedback():
    dt = 0.01
    plant = control.ss(control.c2d(control.tf([1.0], [1.0, 0.4, 1.0]), dt, method="tustin"))
    controller = control.ss(control.c2d(control.tf([2.0, 1.5], [1.0, 0.0]), dt, method="tustin"))  # 2 + 1.5 / s
    assert plant.D[0, 0] != 0 and controller.D[0, 0] != 0
    t = np.arange(800) * dt
    reference = np.where(t >= 0.05, 1.0, 0.0) + 0.3 * np.sin(2.0 * t)
    y = Simulator(_feedback_diagram(controller, plant, reference)).run(n_steps=len(t))["y"]
    expected = control.forced_response(control.feedback(plant * controller, 1), T=t, U=reference).outputs
    # python-control's closed-form matrices drift from the exact recursion by 3e-12 after 8 s, the
    # per-tick solve by 1e-13: compare with python-control over 2 s, with the exact recursion throughout
    np.testing.assert_allclose(y[:200], expected[:200], rtol=0, atol=1e-12)
    np.testing.assert_allclose(y, _closed_loop_40_digits(controller, plant, reference), rtol=0, atol=1e-12)
    assert np.abs(y - expected).max() < 1e-2 * np.abs(y).max()  # same response, not just the start


def test_loop_of_gain_and_sum_is_solved_and_a_matrix_loop_matches_numpy():
    d = Diagram()
    s = d.add("s", Sum("++"))
    g = d.add("g", Gain(0.5))
    c = d.add("c", Constant(1.0))
    d.connect(c.y, s.u0)
    d.connect(s.y, g.u)
    d.connect(g.y, s.u1)
    d.add("p", Probe())
    d.connect(s.y, "p.u")
    assert Simulator(d).run(n_steps=3)["p"].tolist() == [2.0, 2.0, 2.0]  # y = 1 + y / 2

    k = np.array([[0.2, -0.5], [0.3, 0.1]])
    m = Diagram()
    b = m.add("b", Constant([1.0, -2.0]))
    s = m.add("s", Sum("+-"))
    g = m.add("g", Gain(k, matrix=True))
    m.connect(b.y, s.u0)
    m.connect(s.y, g.u)
    m.connect(g.y, s.u1)
    m.add("p", Probe())
    m.connect(s.y, "p.u")
    got = Simulator(m).run(n_steps=1)["p"][0]
    np.testing.assert_allclose(got, np.linalg.solve(np.eye(2) + k, [1.0, -2.0]), rtol=1e-14)


def test_singular_and_multirate_linear_loops_are_refused_with_the_cycle_named():
    d = Diagram()
    s = d.add("s", Sum("++"))
    g = d.add("g", Gain(1.0))
    c = d.add("c", Constant(1.0))
    d.connect(c.y, s.u0)
    d.connect(s.y, g.u)
    d.connect(g.y, s.u1)
    with pytest.raises(
        DiagramError, match=r"algebraic loop: (s\.y -> g\.u, g\.y -> s\.u1|g\.y -> s\.u1, s\.y -> g\.u) is singular"
    ):
        d.compile()
    d.replace("g", Gain(0.5, period=0.02))
    with pytest.raises(DiagramError, match="joins blocks of different periods"):
        d.compile()


def test_a_loop_with_a_nonlinear_block_is_still_refused():
    d = Diagram()
    s = d.add("s", Sum("++"))
    g = d.add("g", Gain(0.5))
    sat = d.add("sat", Saturation(-1.0, 1.0))
    c = d.add("c", Constant(1.0))
    d.connect(c.y, s.u0)
    d.connect(s.y, g.u)
    d.connect(g.y, sat.u)
    d.connect(sat.y, s.u1)
    with pytest.raises(DiagramError, match=r"sat \(Saturation\) is not linear.*break it with a UnitDelay"):
        d.compile()


# -- 18. gain units; a textbook PID from primitives -----------------------------------------------------------


def test_gain_unit_multiplies_the_input_unit():
    from cogblocks.sim.signal import unit_product  # new in issue 13: imported here so older code fails per test

    assert unit_product("1", "1/s") == "1/s" and unit_product("rad", "1/s") == "rad/s"
    assert unit_product("mm/s", "s") == "mm" and unit_product("mm/s^2", "s") == "mm/s"
    d = Diagram()
    c = d.add("c", Constant(1.0, unit="rad"))
    g = d.add("g", Gain(3.0, unit="1/s"))
    d.connect(c.y, g.u)
    d.compile()
    assert g.y.spec.unit == "rad/s"
    with pytest.raises(ValueError, match="Gain: unit: cannot multiply the unit 'm\\+s'"):
        Gain(1.0, unit="m+s")


def test_textbook_pid_from_primitives_matches_its_recursion():
    # the PID of docs/how-to/write-a-block.md, run as written there
    text = (Path(__file__).parents[2] / "docs" / "how-to" / "write-a-block.md").read_text(encoding="utf-8")
    code = re.search(r"## A textbook PID.*?```python\n(.*?)```", text, re.S).group(1)
    namespace: dict = {}
    exec(code, namespace)
    kp, ki, kd, dt = 2.0, 0.7, 0.05, 0.01
    e_values = np.sin(np.arange(300) * 0.05) + 0.2
    d = Diagram()
    e = d.add("e", Playback(e_values))
    pid = d.add("pid", namespace["pid"](kp, ki, kd))
    d.connect(e.y, pid.e)
    d.add("out", Probe())
    d.connect(pid.u, "out.u")
    got = Simulator(d, dt=dt).run(n_steps=len(e_values))["out"]
    assert pid["u"].y.spec.unit == "1" and pid["i"].y.spec.unit == "1"
    integral = np.concatenate([[0.0], np.cumsum(ki * dt * e_values)[:-1]])
    derivative = np.concatenate([[0.0], np.diff(e_values) / dt])
    np.testing.assert_allclose(got, kp * e_values + integral + kd * derivative, rtol=0, atol=1e-12)


# -- 19. run(duration=T): ticks 0 … T − dt ---------------------------------------------------------------------


def test_duration_runs_ticks_and_include_end_adds_the_end_point():
    sim = Simulator(_counter_loop())
    first = sim.run(duration=0.05)
    assert len(first.t) == 5 and first.t[-1] == pytest.approx(0.04) and sim.time == pytest.approx(0.05)
    second = sim.run(duration=0.05)
    assert second.t[0] == pytest.approx(0.05)  # the next run continues at T
    whole = Simulator(_counter_loop()).run(duration=0.1)["p"]
    np.testing.assert_array_equal(np.concatenate([first["p"], second["p"]]), whole)
    with_end = Simulator(_counter_loop()).run(duration=0.05, include_end=True)
    assert len(with_end.t) == 6 and with_end.t[-1] == pytest.approx(0.05)
    with pytest.raises(ValueError, match="include_end applies to run\\(duration=...\\)"):
        sim.run(n_steps=3, include_end=True)
