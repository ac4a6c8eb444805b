"""Mux, Demux, Select and Substitute (cogblocks.blocks.routing): elements in, elements out, units kept."""

import numpy as np
import pytest

from cogblocks.blocks import Demux, Mux, Playback, Probe
from cogblocks.sim import Diagram, DiagramError, Simulator


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
