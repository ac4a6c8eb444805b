"""The blending rule v_a = c·v_h + (1 − c)·v_r with c looked up in w̃, and the ports every blending rule shares."""

from __future__ import annotations

import numpy as np

from cogblocks.amplification.solution import SolutionTable
from cogblocks.blocks.specs import COUNT, VELOCITY
from cogblocks.sim import Block, Signal

__all__ = ["BLENDING_INPUTS", "BLENDING_OUTPUTS", "VelocityBlender", "add_blending_ports", "blend"]

_BLENDING_INPUT_SPECS = {
    "v_h": VELOCITY,
    "v_r": VELOCITY,
    "v_u": VELOCITY,
    "nearest": COUNT,
    "reference": COUNT,
    "decisions": COUNT,
}
#: The ports every blending rule has (:func:`add_blending_ports`).
BLENDING_INPUTS = tuple(_BLENDING_INPUT_SPECS)
BLENDING_OUTPUTS = ("v_a", "c")


def add_blending_ports(block: Block) -> None:
    """Declare the ports every blending rule shares, so that rules swap in the architecture.

    Inputs ``v_h``, ``v_r``, ``v_u`` (zero if unconnected), shape (3,), mm/s, and the projector's
    decision ``nearest``, ``reference``, ``decisions`` (int64); outputs ``v_a`` (mm/s) and ``c``.
    """
    for name, spec in _BLENDING_INPUT_SPECS.items():
        block.add_input(name, spec, default=np.zeros(3) if name == "v_u" else None)
    block.add_output("v_a", VELOCITY)
    block.add_output("c", Signal(unit="1"), initial=1.0)


def blend(c: float, v_h: np.ndarray, v_r: np.ndarray, out: np.ndarray) -> None:
    """``out = c·v_h + (1 − c)·v_r``, in place; ``v_r`` is not read when ``c = 1`` (0·NaN is NaN)."""
    np.multiply(c, v_h, out=out)
    if c != 1.0:
        out += (1.0 - c) * v_r


class VelocityBlender(Block):
    """``v_a = c·v_h + (1 − c)·v_r + v_u`` with ``c = w̃(η_i, v_r)`` from a :class:`SolutionTable`.

    Before the projector's first decision ``c = 1``: the human signal passes through. Afterwards ``c``
    is looked up for the projector's current pair, so it changes only when a decision does.

    Ports
    -----
    v_h : input, shape (3,), mm/s
        The human velocity.
    v_r : input, shape (3,), mm/s
        The reference velocity (from :class:`LibraryProjector`).
    v_u : input, shape (3,), mm/s, optional
        Correction term (zero if unconnected).
    nearest, reference, decisions : input, int64
        The projector's decision.
    v_a : output, shape (3,), mm/s
        The altered velocity.
    c : output, scalar
        The blending coefficient in use.

    Parameters
    ----------
    table : SolutionTable
        w̃ on the projector's library.

    Notes
    -----
    Bad data policy: a non-finite ``v_h`` or ``v_u``, or a non-finite ``v_r`` while it is
    weighted (``c < 1``), gives a non-finite ``v_a`` (:class:`VelocityPositionComputer` then holds its
    position); with ``c = 1`` the reference is not used at all.
    """

    def __init__(self, table: SolutionTable, *, period: float | None = None) -> None:
        super().__init__(period=period)
        if not isinstance(table, SolutionTable):
            raise ValueError(f"VelocityBlender: table must be a SolutionTable, got {type(table).__name__}")
        self.table = table
        add_blending_ports(self)

    def output(self, k: int) -> None:
        if int(self.decisions.value) > 0:
            c = self.table.lookup(int(self.nearest.value), int(self.reference.value))
        else:
            c = 1.0
        self.c.value[...] = c
        blend(c, self.v_h.value, self.v_r.value, self.v_a.value)
        self.v_a.value += self.v_u.value
