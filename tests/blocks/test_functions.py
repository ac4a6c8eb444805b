"""Gain, Sum, Saturation and Function (cogblocks.blocks.functions) against independent computations."""

import numpy as np
import pytest

from cogblocks.blocks import (
    Constant,
    Function,
    Gain,
    Playback,
    Probe,
    Saturation,
    Sum,
)
from cogblocks.sim import Diagram, DiagramError, Signal, SimulationError, Simulator
from tests.blocks.chain_helpers import run_chain


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


def test_saturation():
    u = np.linspace(-3, 3, 13)
    np.testing.assert_array_equal(run_chain(u, Saturation(-1.0, 2.0)), np.clip(u, -1.0, 2.0))
    with pytest.raises(ValueError, match=r"Saturation: upper must be a finite number in \[2.0, inf\), got 1.0"):
        Saturation(2.0, 1.0)


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
