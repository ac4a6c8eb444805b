"""Input and output ports of a block."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from cogblocks.sim.signal import Signal

if TYPE_CHECKING:
    from cogblocks.sim.block import Block

__all__ = ["Input", "Output", "Port"]


class Port:
    """A named, typed end point of a block.

    ``value`` is the NumPy array that carries the signal. For an output it is
    allocated when the diagram is compiled and must be written *in place*
    (``self.y.value[...] = x``); for an input it is bound, at compile time, to the
    very array of the output that drives it, so reading costs no copy.
    """

    __slots__ = ("block", "name", "spec", "value")

    def __init__(self, block: Block, name: str, spec: Signal | None) -> None:
        self.block = block
        self.name = name
        self.spec = spec
        self.value: np.ndarray = np.zeros(()) if spec is None or not spec.concrete else spec.zeros()

    @property
    def qualname(self) -> str:
        """``block.port``, with the block's name in its diagram if it has one."""
        return f"{self.block.name or type(self.block).__name__}.{self.name}"

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.qualname}: {self.spec}>"


class Input(Port):
    """An input port.

    Parameters beyond the spec: ``default`` (value used when nothing drives the
    input; without it an unconnected input is a compile error) and
    ``feedthrough`` (whether the block's outputs at a tick read this input at the
    same tick; ``False`` for inputs read only in ``update``). After compiling,
    ``driven`` tells whether a wire or a diagram input feeds it (``False``: it
    reads its default).
    """

    __slots__ = ("declared", "default", "feedthrough", "driven")

    def __init__(
        self,
        block: Block,
        name: str,
        spec: Signal,
        default: Any = None,
        feedthrough: bool = True,
    ) -> None:
        super().__init__(block, name, spec)
        self.declared = spec
        self.default = None if default is None else np.asarray(default)
        self.feedthrough = bool(feedthrough)
        # set when compiled: False when the input reads its (constant, checked) default
        self.driven = True


class Output(Port):
    """An output port.

    Its spec is either given, or inferred at compile time from an input of the
    same block (``like="u"``, optionally with some fields overridden).
    """

    __slots__ = ("like", "like_overrides", "initial")

    def __init__(
        self,
        block: Block,
        name: str,
        spec: Signal | None,
        like: str | None = None,
        like_overrides: dict[str, Any] | None = None,
        initial: Any = None,
    ) -> None:
        super().__init__(block, name, spec)
        self.like = like
        self.like_overrides = like_overrides or {}
        self.initial = None if initial is None else np.asarray(initial)
