"""A chain of blocks behind a playback, probed at its end: what the block tests run."""

from cogblocks.blocks import Playback, Probe
from cogblocks.sim import Diagram, Simulator


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
