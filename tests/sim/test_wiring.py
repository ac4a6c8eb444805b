"""Port specs, connection checks, unconnected and doubly driven inputs."""

import numpy as np
import pytest

from cogblocks.blocks import Constant, Gain, Integrator, Probe, Sum, UnitDelay
from cogblocks.sim import ANY, Block, Diagram, DiagramError, Signal, Simulator


class Source(Block):
    def __init__(self, **fields):
        super().__init__()
        self.add_output("y", **fields)


class Sink(Block):
    def __init__(self, default=None, **fields):
        super().__init__()
        self.add_input("u", default=default, **fields)


def test_signal_mismatch_and_merge():
    a = Signal(shape=(3,), unit="mm")
    assert a.mismatch(Signal(shape=(3,), unit="mm")) is None
    assert a.mismatch(Signal(shape=(3,), unit="mm/s")) == "unit 'mm' != 'mm/s'"
    assert a.mismatch(Signal(shape=(2,), unit="mm")) == "shape (3,) != (2,)"
    assert a.mismatch(Signal(shape=(3,), unit="mm", wrapped=True)) == "wrapped False != True"
    assert a.mismatch(ANY) is None
    assert ANY.merge(a) == a
    assert not ANY.concrete and a.concrete
    with pytest.raises(ValueError, match="shape must be a tuple of non-negative ints"):
        Signal(shape=(-1,))


@pytest.mark.parametrize(
    "src, dst, problem",
    [
        (dict(shape=(3,), unit="mm"), dict(shape=(3,), unit="mm/s"), "unit 'mm' != 'mm/s'"),
        (dict(shape=(3,), unit="mm"), dict(shape=(2,), unit="mm"), r"shape \(3,\) != \(2,\)"),
        (dict(unit="rad", wrapped=True), dict(unit="rad", wrapped=False), "wrapped True != False"),
        (dict(dtype=bool), dict(), "dtype"),
    ],
)
def test_connect_mismatch_names_both_ports_and_specs(src, dst, problem):
    d = Diagram()
    a = d.add("src", Source(**src))
    b = d.add("dst", Sink(**dst))
    with pytest.raises(DiagramError, match=problem) as err:
        d.connect(a.y, b.u)
    msg = str(err.value)
    assert "src.y" in msg and "dst.u" in msg
    assert str(Signal(**src)) in msg and str(Signal(**dst)) in msg


def test_generic_block_mismatch_found_at_compile_with_both_ends():
    d = Diagram()
    a = d.add("src", Source(shape=(3,), unit="mm"))
    g = d.add("g", Gain(2.0))
    s = d.add("dst", Sink(shape=(3,), unit="mm/s"))
    d.connect(a.y, g.u)
    d.connect(g.y, s.u)  # g.y's spec is not known yet
    with pytest.raises(DiagramError, match=r"g\.y .*unit='mm'.* dst\.u .*unit='mm/s'.*unit 'mm' != 'mm/s'"):
        d.compile()


def test_unconnected_input_is_a_compile_error_unless_default():
    d = Diagram()
    d.add("a", Sink(unit="mm"))
    d.add("b", Sink(default=1.5, unit="mm"))
    with pytest.raises(DiagramError, match=r"unconnected input\(s\) with no default: a\.u;"):
        d.compile()


def test_default_value_is_read():
    d = Diagram()
    g = d.add("g", Gain(2.0))
    g.u.default = np.array(1.5)
    d.add("p", Probe())
    d.connect(g.y, "p.u")
    assert Simulator(d).run(n_steps=3)["p"].tolist() == [3.0, 3.0, 3.0]


def test_input_driven_twice_is_refused():
    d = Diagram()
    a = d.add("a", Constant(1.0))
    b = d.add("b", Constant(2.0))
    s = d.add("s", Sink())
    d.connect(a.y, s.u)
    with pytest.raises(DiagramError, match=r"input s\.u is already driven by a\.y; cannot also connect b\.y"):
        d.connect(b.y, s.u)


def test_bad_references():
    d = Diagram()
    d.add("a", Constant(1.0))
    with pytest.raises(DiagramError, match="block 'a' \\(Constant\\) has no output 'z'; it has \\['y'\\]"):
        d.connect("a.z", "a.y")
    with pytest.raises(DiagramError, match="does not name a port of a block of this diagram"):
        d.connect("nope.y", "a.y")
    stranger = Constant(3.0)
    with pytest.raises(DiagramError, match="not a direct child of this diagram"):
        d.connect(stranger.y, "a.y")
    with pytest.raises(DiagramError, match="already has a block named 'a'"):
        d.add("a", Constant(2.0))
    with pytest.raises(DiagramError, match="block names must be identifiers"):
        d.add("a b", Constant(2.0))
    with pytest.raises(DiagramError, match="expected an input port"):
        d.connect("a.y", d["a"].y)


def test_block_without_super_init_is_reported():
    class Bad(Block):
        def __init__(self):
            pass

    with pytest.raises(DiagramError, match="must call super\\(\\).__init__\\(\\)"):
        Diagram().add("bad", Bad())

    class AlsoBad(Block):
        def __init__(self):
            self.add_input("u")

    with pytest.raises(TypeError, match="must call super\\(\\).__init__\\(\\) before declaring"):
        AlsoBad()


def test_port_name_clash_is_refused():
    class Clash(Block):
        def __init__(self):
            super().__init__()
            self.add_input("output")

    with pytest.raises(ValueError, match="'output' would shadow an attribute"):
        Clash()


def test_sum_checks_its_inputs_agree():
    d = Diagram()
    a = d.add("a", Source(unit="mm"))
    b = d.add("b", Source(unit="rad"))
    s = d.add("s", Sum("+-"))
    d.connect(a.y, s.u0)
    d.connect(b.y, s.u1)
    with pytest.raises(DiagramError, match="s: all inputs must share shape and unit"):
        d.compile()


def test_generic_feedback_loop_needs_an_explicit_spec():
    d = Diagram()
    delay = d.add("delay", UnitDelay())
    gain = d.add("gain", Gain(0.5))
    d.connect(delay.y, gain.u)
    d.connect(gain.y, delay.u)
    with pytest.raises(DiagramError, match="cannot infer the spec of .*give one of them an explicit spec"):
        d.compile()
    d2 = Diagram()
    delay = d2.add("delay", UnitDelay(1.0, shape=(), unit="1"))
    gain = d2.add("gain", Gain(0.5))
    d2.connect(delay.y, gain.u)
    d2.connect(gain.y, delay.u)
    d2.add("p", Probe())
    d2.connect(delay.y, "p.u")
    assert Simulator(d2).run(n_steps=4)["p"].tolist() == [1.0, 0.5, 0.25, 0.125]


def test_integrator_unit_follows_input():
    d = Diagram()
    v = d.add("v", Constant([1.0, 2.0, 3.0], unit="mm/s"))
    x = d.add("x", Integrator())
    d.connect(v.y, x.u)
    d.add("p", Sink(shape=(3,), unit="mm"))
    d.connect(x.y, "p.u")
    d.compile()
    assert x.y.spec == Signal(shape=(3,), unit="mm")
