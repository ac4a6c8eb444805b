"""Two-phase ticks, feedthrough ordering, algebraic loops, multirate."""

import numpy as np
import pytest

from cogblocks.blocks import Constant, Gain, Integrator, Playback, Probe, Saturation, Sum, UnitDelay
from cogblocks.sim import Block, Diagram, DiagramError, SimulationError, Simulator


class Counter(Block):
    """Outputs how many times it has been updated."""

    def __init__(self, period=None):
        super().__init__(period=period)
        self.add_output("y")
        self.add_state("n", 0)

    def output(self, k):
        self.y.value[...] = self.n

    def update(self, k):
        self.n += 1


def test_outputs_computed_in_dependency_order_regardless_of_insertion():
    d = Diagram()
    # added downstream-first on purpose
    g2 = d.add("g2", Gain(10.0))
    g1 = d.add("g1", Gain(2.0))
    src = d.add("src", Playback(np.arange(5.0)))
    d.connect(g1.y, g2.u)
    d.connect(src.y, g1.u)
    d.add("p", Probe())
    d.connect(g2.y, "p.u")
    compiled = d.compile()
    order = list(compiled.blocks)
    assert order.index("src") < order.index("g1") < order.index("g2")
    assert Simulator(compiled).run(n_steps=5)["p"].tolist() == [0.0, 20.0, 40.0, 60.0, 80.0]


def test_algebraic_loop_is_refused_with_cycle_named():
    # a loop through a nonlinear block (linear loops of Gain/Sum are solved: test_new_user_engine.py)
    d = Diagram()
    s = d.add("s", Sum("++"))
    g = d.add("g", Saturation(-10.0, 10.0))
    c = d.add("c", Constant(1.0))
    d.connect(c.y, s.u0)
    d.connect(s.y, g.u)
    d.connect(g.y, s.u1)
    with pytest.raises(
        DiagramError,
        match=r"algebraic loop: (s\.y -> g\.u, g\.y -> s\.u1|g\.y -> s\.u1, s\.y -> g\.u) .* "
        r"g \(Saturation\) is not linear",
    ):
        d.compile()


def test_loop_through_a_non_feedthrough_block_compiles_and_is_two_phase():
    # x[k+1] = x[k] + dt * (1 - x[k]) : an integrator in a feedback loop
    d = Diagram()
    c = d.add("c", Constant(1.0))
    s = d.add("s", Sum("+-"))
    x = d.add("x", Integrator(unit="1"))  # integrating "1" would give "s", which the Sum refuses
    d.connect(c.y, s.u0)
    d.connect(x.y, s.u1)
    d.connect(s.y, x.u)
    d.add("p", Probe())
    d.connect(x.y, "p.u")
    got = Simulator(d, dt=0.1).run(n_steps=6)["p"]
    expected = [0.0]
    for _ in range(5):
        expected.append(expected[-1] + 0.1 * (1 - expected[-1]))
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-15)


def test_unit_delay_chain_is_a_shift():
    d = Diagram()
    src = d.add("src", Playback(np.arange(1.0, 7.0)))
    d1 = d.add("d1", UnitDelay(-1.0))
    d2 = d.add("d2", UnitDelay(-2.0))
    d.connect(src.y, d1.u)
    d.connect(d1.y, d2.u)
    d.add("p", Probe())
    d.connect(d2.y, "p.u")
    assert Simulator(d).run(n_steps=6)["p"].tolist() == [-2.0, -1.0, 1.0, 2.0, 3.0, 4.0]


def test_multirate_zero_order_hold_and_block_dt():
    d = Diagram()
    src = d.add("src", Playback(np.arange(100.0)))
    slow = d.add("slow", Gain(1.0), period=0.03)
    d.connect(src.y, slow.u)
    d.add("p", Probe())
    d.connect(slow.y, "p.u")
    counter = d.add("count", Counter(), period=0.05)
    d.add("pc", Probe())
    d.connect(counter.y, "pc.u")
    trace = Simulator(d, dt=0.01).run(n_steps=10)
    # the slow gain samples ticks 0, 3, 6, 9 and holds in between
    assert trace["p"].tolist() == [0, 0, 0, 3, 3, 3, 6, 6, 6, 9]
    assert trace["pc"].tolist() == [0, 0, 0, 0, 0, 1, 1, 1, 1, 1]
    assert slow.dt == pytest.approx(0.03) and slow.every == 3
    assert counter.every == 5


def test_integrator_uses_its_own_period():
    d = Diagram()
    c = d.add("c", Constant(1.0))
    x = d.add("x", Integrator(), period=0.05)
    d.connect(c.y, x.u)
    d.add("p", Probe())
    d.connect(x.y, "p.u")
    got = Simulator(d, dt=0.01).run(n_steps=11)["p"]
    np.testing.assert_allclose(got, [0.0] * 5 + [0.05] * 5 + [0.10], atol=1e-15)


def test_playback_multirate_plays_one_row_per_block_step():
    d = Diagram()
    src = d.add("src", Playback(np.arange(10.0)), period=0.02)
    d.add("p", Probe())
    d.connect(src.y, "p.u")
    assert Simulator(d).run(n_steps=6)["p"].tolist() == [0, 0, 1, 1, 2, 2]


@pytest.mark.parametrize("period", [0.015, 0.0, -0.01, 0.005])
def test_period_not_a_multiple_of_base_step_is_refused(period):
    d = Diagram()
    d.add("c", Counter(period=period))
    with pytest.raises(
        DiagramError,
        match=rf"block 'c' asks for a period of {period!r} s, which is not a positive multiple of the base step 0.01 s",
    ):
        d.compile()


def test_sub_diagram_period_is_inherited():
    inner = Diagram(period=0.02)
    inner.add("c", Counter())
    inner.expose_output("y", "c.y")
    d = Diagram()
    d.add("inner", inner)
    compiled = d.compile()
    assert compiled.blocks["inner.c"].every == 2


def test_huge_hyperperiod_falls_back_to_per_tick_schedule():
    d = Diagram()
    periods = [0.07, 0.11, 0.13, 0.17, 0.19]  # lcm 323323 ticks > table limit
    for i, p in enumerate(periods):
        d.add(f"c{i}", Counter(period=p))
        d.add(f"p{i}", Probe())
        d.connect(f"c{i}.y", f"p{i}.u")
    compiled = d.compile()
    assert compiled._phases is None
    trace = Simulator(compiled).run(n_steps=40)
    for i, p in enumerate(periods):
        every = round(p / 0.01)
        expected = [(k // every) for k in range(40)]
        assert trace[f"p{i}"].tolist() == expected


def test_rebinding_an_output_array_is_caught_on_first_tick():
    class Sloppy(Block):
        def __init__(self):
            super().__init__()
            self.add_output("y")

        def output(self, k):
            self.y.value = np.array(1.0)

    d = Diagram()
    d.add("s", Sloppy())
    with pytest.raises(SimulationError, match="block 's' replaced the array of its output 'y'"):
        Simulator(d).run(n_steps=3)


def test_bad_dt_is_refused():
    with pytest.raises(DiagramError, match="base step dt must be a positive number"):
        Diagram().compile(dt=0.0)
