"""Hierarchy, live stepping, snapshots, rendering, traces."""

import subprocess
import sys

import numpy as np
import pytest

from cogblocks.blocks import Gain, Integrator, LowPass, Playback, Probe, Sum
from cogblocks.sim import Block, Diagram, DiagramError, Signal, Simulator, Trace
from cogblocks.sync import KuramotoGroup, OrderParameter

OMEGA = [2.7151, 2.9299, 4.0344, 2.1476, 3.9117, 3.7429, 3.2827]


class Noise(Block):
    """Seeded Gaussian noise: exercises Generator state in snapshots."""

    def __init__(self, seed):
        super().__init__()
        self.add_input("u")
        self.add_output("y")
        self.add_state("rng", np.random.default_rng(seed))

    def output(self, k):
        self.y.value[...] = self.u.value + self.rng.normal()


def _controller() -> Diagram:
    """e = r - y; u = 2 e filtered: a sub-diagram with exposed ports."""
    c = Diagram()
    s = c.add("err", Sum("+-"))
    g = c.add("gain", Gain(2.0))
    f = c.add("filt", LowPass(5.0))
    c.connect(s.y, g.u)
    c.connect(g.y, f.u)
    c.expose_input("r", s.u0)
    c.expose_input("y", s.u1)
    c.expose_output("u", f.y)
    return c


def _plant_loop(nested: bool) -> Diagram:
    d = Diagram()
    ref = d.add("ref", Playback(np.sin(np.arange(300) * 0.05)))
    plant = d.add("plant", Integrator(unit="1"))
    noise = d.add("noise", Noise(3))
    d.connect(plant.y, noise.u)
    if nested:
        ctrl = d.add("ctrl", _controller())
        d.connect(ref.y, ctrl.r)
        d.connect(noise.y, ctrl.y)
        d.connect(ctrl.u, plant.u)
    else:
        s = d.add("err", Sum("+-"))
        g = d.add("gain", Gain(2.0))
        f = d.add("filt", LowPass(5.0))
        d.connect(ref.y, s.u0)
        d.connect(noise.y, s.u1)
        d.connect(s.y, g.u)
        d.connect(g.y, f.u)
        d.connect(f.y, plant.u)
    d.add("p", Probe())
    d.connect(plant.y, "p.u")
    return d


def test_nested_diagram_gives_same_trace_as_flattened():
    nested = Simulator(_plant_loop(True)).run(n_steps=300)
    flat = Simulator(_plant_loop(False)).run(n_steps=300)
    assert np.array_equal(nested["p"], flat["p"])
    assert np.array_equal(nested.t, flat.t)
    assert np.ptp(nested["p"]) > 0.1  # the loop really moved


def test_nested_paths_and_probes_through_sub_diagrams():
    d = _plant_loop(True)
    compiled = d.compile()
    assert "ctrl.gain" in compiled.blocks and "ctrl.filt" in compiled.blocks
    trace = Simulator(compiled, probes={"u": "ctrl.u", "e": "ctrl.err.y"}).run(n_steps=20)
    assert set(trace) == {"p", "u", "e"}
    np.testing.assert_allclose(trace["u"][:-1], np.diff(trace["p"]) / 0.01, atol=1e-12)  # p[k+1] = p[k] + dt u[k]
    with pytest.raises(DiagramError, match="'ctrl.nope' is not an output port"):
        Simulator(compiled, probes=["ctrl.nope"])


def test_sub_diagram_input_left_unconnected_names_the_leaf():
    d = Diagram()
    d.add("ctrl", _controller())
    with pytest.raises(DiagramError, match=r"ctrl\.err\.u0"):
        d.compile()


def test_replace_keeps_wires_and_checks_ports():
    d = _plant_loop(True)
    old = d.replace("ctrl.gain", Gain(3.0))
    assert isinstance(old, Gain) and old.k == 2.0
    assert d["ctrl.gain"].k == 3.0
    Simulator(d).run(n_steps=5)
    with pytest.raises(DiagramError, match="cannot replace 'ctrl.gain'"):
        d.replace("ctrl.gain", Integrator())  # same port names: allowed
        d.replace("ctrl.gain", Sum("++"))
    with pytest.raises(KeyError, match="no block 'ctrl.zzz'"):
        d.replace("ctrl.zzz", Gain(1.0))


def test_snapshot_restore_gives_identical_trace():
    sim = Simulator(_plant_loop(True))
    sim.run(n_steps=500 - 300)  # the playback holds its last value past 300: fine
    sim.run(n_steps=300)
    snap = sim.state_dict()
    first = sim.run(n_steps=500)
    sim.load_state_dict(snap)
    second = sim.run(n_steps=500)
    assert np.array_equal(first["p"], second["p"])
    assert np.array_equal(first.t, second.t)
    assert first.t[0] == pytest.approx(5.0)


def test_snapshot_restores_held_outputs_of_slow_blocks():
    d = Diagram()
    src = d.add("src", Playback(np.arange(1000.0)))
    slow = d.add("slow", Gain(1.0), period=0.07)
    d.connect(src.y, slow.u)
    d.add("p", Probe())
    d.connect(slow.y, "p.u")
    sim = Simulator(d)
    sim.run(n_steps=503)
    snap = sim.state_dict()
    a = sim.run(n_steps=50)["p"]
    sim.load_state_dict(snap)
    b = sim.run(n_steps=50)["p"]
    assert np.array_equal(a, b) and a[0] == 497.0


def test_load_state_dict_for_another_diagram_is_refused():
    sim_a = Simulator(_plant_loop(True))
    sim_b = Simulator(_plant_loop(False))
    with pytest.raises(ValueError, match="state dict is for blocks"):
        sim_b.load_state_dict(sim_a.state_dict())


def test_reset_rewinds():
    sim = Simulator(_plant_loop(True))
    a = sim.run(n_steps=100)
    sim.reset()
    b = sim.run(n_steps=100)
    assert np.array_equal(a["p"], b["p"]) and b.t[0] == 0.0


def test_live_step_matches_batch_run():
    def diagram():
        d = Diagram()
        g = d.add("gain", Gain(3.0))
        f = d.add("f", LowPass(8.0))
        d.connect(g.y, f.u)
        d.expose_input("x", g.u, spec=Signal(unit="mm"))
        d.expose_output("y", f.y)
        d.add("p", Probe())
        d.connect(f.y, "p.u")
        return d

    x = np.cos(np.arange(50) * 0.3)
    batch = Simulator(diagram()).run(n_steps=50, inputs={"x": x})["p"]
    live = diagram().compile()
    got = [live.step(x=v)["y"] for v in x]
    np.testing.assert_array_equal(got, batch)
    assert live.input_names == ("x",) and live.output_names == ("y",)
    with pytest.raises(KeyError, match="the diagram has no input 'z'"):
        live.step(z=1.0)
    fresh = diagram().compile()
    with pytest.raises(ValueError, match=r"the first step needs every diagram input; missing \['x'\]"):
        fresh.step()
    with pytest.raises(ValueError, match="run\\(\\) needs values for the diagram inputs \\['x'\\]"):
        Simulator(diagram()).run(n_steps=3)
    with pytest.raises(ValueError, match="input 'x': expected a constant of shape"):
        Simulator(diagram()).run(n_steps=3, inputs={"x": np.zeros((2, 2))})


def test_inputs_as_callable_and_constant():
    d = Diagram()
    g = d.add("g", Gain(1.0))
    d.expose_input("x", g.u, spec=Signal())
    d.add("p", Probe())
    d.connect(g.y, "p.u")
    assert Simulator(d).run(n_steps=3, inputs={"x": lambda t: 100 * t})["p"].tolist() == pytest.approx([0, 1, 2])
    assert Simulator(d).run(n_steps=2, inputs={"x": 7.0})["p"].tolist() == [7.0, 7.0]


def test_run_arguments_are_checked():
    sim = Simulator(_plant_loop(True))
    with pytest.raises(ValueError, match="give exactly one of duration"):
        sim.run()
    with pytest.raises(ValueError, match="not a whole number of base steps"):
        sim.run(0.015)
    with pytest.raises(ValueError, match="n_steps must be a non-negative integer"):
        sim.run(n_steps=-1)
    with pytest.raises(ValueError, match="decimate must be an integer >= 1"):
        Simulator(_plant_loop(True), decimate=0)
    assert len(sim.run(0.5).t) == 50


def test_decimation_keeps_every_nth_sample():
    full = Simulator(_plant_loop(True)).run(n_steps=101)
    dec = Simulator(_plant_loop(True), decimate=10).run(n_steps=101)
    assert len(dec.t) == 11
    np.testing.assert_array_equal(dec["p"], full["p"][::10])
    np.testing.assert_allclose(dec.t, full.t[::10])


def test_trace_to_pandas_and_units():
    d = Diagram()
    g = d.add("group", KuramotoGroup(OMEGA, 4.4 / 7))
    o = d.add("order", OrderParameter())
    d.connect(g.theta, o.theta)
    trace = Simulator(d, probes={"theta": "group.theta", "r": "order.r"}).run(n_steps=10)
    df = trace.to_pandas()
    assert list(df.columns) == [f"theta[{i}]" for i in range(7)] + ["r"]
    np.testing.assert_array_equal(df["theta[3]"].to_numpy(), trace["theta"][:, 3])
    assert df.index.name == "t" and trace.units == {"theta": "rad", "r": "1"}
    with pytest.raises(KeyError, match="no signal 'x' in the trace"):
        trace["x"]
    with pytest.raises(ValueError, match="has 2 samples but the time vector has 3"):
        Trace(np.zeros(3), {"a": np.zeros(2)})


def test_trace_plot_labels_every_line():
    import matplotlib

    matplotlib.use("Agg")
    trace = Trace(np.arange(3) * 0.01, {"a": np.zeros(3), "v": np.ones((3, 2))})
    ax = trace.plot()
    assert [line.get_label() for line in ax.get_lines()] == ["a", "v[0]", "v[1]"]
    np.testing.assert_array_equal(ax.get_lines()[2].get_ydata(), np.ones(3))


def test_mermaid_and_dot_show_blocks_wires_and_subgraphs():
    d = _plant_loop(True)
    mermaid = d.to_mermaid()
    assert mermaid.startswith("flowchart LR")
    assert 'subgraph ctrl["ctrl: Diagram"]' in mermaid
    assert 'ctrl__gain["gain: Gain"]' in mermaid
    assert "ref -->|y → r| ctrl__in_r" in mermaid
    assert "ctrl__in_r -->|u0| ctrl__err" in mermaid
    dot = d.to_dot()
    assert dot.startswith("digraph cogblocks {") and dot.rstrip().endswith("}")
    assert "subgraph cluster_ctrl {" in dot
    assert 'plant -> noise [label="y → u"];' in dot


def test_progress_bar_only_when_asked_or_in_a_terminal(capsys):
    Simulator(_plant_loop(True), progress=True).run(n_steps=2000)
    assert "simulating" in capsys.readouterr().err
    Simulator(_plant_loop(True)).run(n_steps=30000)  # not a terminal under pytest
    assert capsys.readouterr().err == ""


def test_progress_bar_shows_in_a_terminal_without_ci():
    import os
    import pty

    code = (
        "from cogblocks.sync import KuramotoGroup\n"
        "from cogblocks.sim import Diagram, Simulator\n"
        "d = Diagram(); d.add('g', KuramotoGroup([1.0, 2.0], 1.0))\n"
        "Simulator(d).run(n_steps=30000)\n"
    )
    import fcntl
    import struct
    import termios

    master, slave = pty.openpty()  # the child's stderr is a terminal ...
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))  # ... with a width, as real ones have
    env = {k: v for k, v in os.environ.items() if k != "CI"}
    proc = subprocess.run([sys.executable, "-c", code], stderr=slave, env=env, timeout=120)
    os.close(slave)
    out = b""
    try:
        while chunk := os.read(master, 4096):
            out += chunk
    except OSError:  # EIO once the pty is drained
        pass
    os.close(master)
    assert proc.returncode == 0
    assert b"simulating" in out


def test_top_level_outputs_can_be_probed_by_name():
    d = Diagram()
    g = d.add("g", Gain(2.0))
    d.expose_input("x", g.u, spec=Signal())
    d.expose_output("y", g.y)
    trace = Simulator(d, probes=["y"]).run(n_steps=2, inputs={"x": 3.0})
    assert trace["y"].tolist() == [6.0, 6.0]


def test_constant_keeps_flags_and_counters():
    from cogblocks.blocks import Constant

    d = Diagram()
    d.add("flag", Constant(True))
    d.add("count", Constant(3))
    trace = Simulator(d, probes=["flag.y", "count.y"]).run(n_steps=2)
    assert trace["flag.y"].dtype == bool and trace["flag.y"].tolist() == [True, True]
    assert trace["count.y"].dtype.kind == "i"


def test_reset_and_load_write_array_state_in_place():
    class Holder(Block):
        def __init__(self):
            super().__init__()
            self.add_output("y")
            self.add_state("x", np.zeros(2))

        def output(self, k):
            self.y.value[...] = self.x[0]

        def update(self, k):
            self.x += 1.0

    d = Diagram()
    h = d.add("h", Holder())
    sim = Simulator(d)
    alias = h.x
    sim.run(n_steps=3)
    snap = sim.state_dict()
    sim.run(n_steps=2)
    sim.load_state_dict(snap)
    assert h.x is alias and alias.tolist() == [3.0, 3.0]
    sim.reset()
    assert h.x is alias and alias.tolist() == [0.0, 0.0]
