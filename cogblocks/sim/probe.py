"""The Probe sink: a named point whose input the Simulator records."""

from __future__ import annotations

from cogblocks.sim.block import Block
from cogblocks.sim.signal import ANY

__all__ = ["Probe"]


class Probe(Block):
    """Mark a signal for recording; the Simulator records every Probe under its path.

    Ports: input ``u`` (any spec).

    Notes
    -----
    Bad data policy: records what it is given, NaN included; it has no output.
    """

    batchable = True  # only read: records the batched signal as it is

    def __init__(self) -> None:
        super().__init__()
        self.add_input("u", ANY)
