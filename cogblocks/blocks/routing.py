"""Routing: stack signals into a vector, split one, pick or replace an element."""

from __future__ import annotations

from cogblocks.sim import Block, Signal
from cogblocks.sim.params import (
    positive_int,
    unit_arg,
    wrapped_arg,
)

__all__ = ["Demux", "Mux", "Select", "Substitute"]


class Mux(Block):
    """Stack ``n`` scalar inputs ``u0 … u{n-1}`` into a vector output ``y`` of shape ``(n,)``.

    Notes
    -----
    Bad data policy: stateless and element-wise, so a non-finite input element
    gives a non-finite output element on the same tick (as in NumPy) and
    nothing else; blocks with memory downstream decide how to treat it.
    """

    def __init__(self, n: int, *, period: float | None = None) -> None:
        super().__init__(period=period)
        self.n = positive_int(self, "n", n)
        self._ins = [self.add_input(f"u{i}", Signal(shape=(), dtype=None, unit=None, wrapped=None)) for i in range(n)]
        self.add_output("y", like="u0", shape=(n,))

    def setup(self) -> None:
        first = self.u0.spec
        for port in self._ins[1:]:
            if port.spec.unit != first.unit or port.spec.wrapped != first.wrapped:
                raise self._fail(f"all inputs must share unit and wrapping; u0 is {first}, {port.name} is {port.spec}")

    batchable = True

    def output(self, k: int) -> None:
        y = self.y.value
        for i, port in enumerate(self._ins):
            y[..., i] = port.value


class Demux(Block):
    """Split a vector input ``u`` of shape ``(n,)`` into scalar outputs ``y0 … y{n-1}``.

    Notes
    -----
    Bad data policy: stateless and element-wise, so a non-finite input element
    gives a non-finite output element on the same tick (as in NumPy) and
    nothing else; blocks with memory downstream decide how to treat it.
    """

    def __init__(
        self, n: int, *, unit: str | None = None, wrapped: bool | None = None, period: float | None = None
    ) -> None:
        super().__init__(period=period)
        self.n = positive_int(self, "n", n)
        unit = unit_arg(self, "unit", unit, optional=True)
        wrapped = wrapped_arg(self, "wrapped", wrapped, optional=True)
        self.add_input("u", Signal(shape=(n,), dtype=None, unit=unit, wrapped=wrapped))
        self._outs = [self.add_output(f"y{i}", like="u", shape=()) for i in range(n)]

    batchable = True

    def output(self, k: int) -> None:
        u = self.u.value
        for i, port in enumerate(self._outs):
            port.value[...] = u[..., i]


class _Indexed(Block):
    """Shared set-up of the blocks that address one element of a vector input ``u``."""

    def __init__(self, index: int, period: float | None) -> None:
        super().__init__(period=period)
        self.index = positive_int(self, "index", index, minimum=0)
        self.add_input("u", Signal(shape=None, dtype=None, unit=None, wrapped=None))

    def setup(self) -> None:
        shape = self.u.spec.shape
        if len(shape) != 1 or self.index >= shape[0]:
            raise self._fail(f"index {self.index} does not fit an input of shape {shape}")


class Select(_Indexed):
    """Pick one element of a vector: ``y = u[index]``.

    Ports: input ``u`` (shape (n,)), output ``y`` (scalar, same unit and wrapping).

    Notes
    -----
    Bad data policy: stateless and element-wise, so a non-finite input element
    gives a non-finite output element on the same tick (as in NumPy) and
    nothing else; blocks with memory downstream decide how to treat it.
    """

    def __init__(self, index: int, *, period: float | None = None) -> None:
        super().__init__(index, period)
        self.add_output("y", like="u", shape=())

    batchable = True

    def output(self, k: int) -> None:
        self.y.value[...] = self.u.value[..., self.index]


class Substitute(_Indexed):
    """Replace one element of a vector: ``y = u`` with ``y[index] = v``.

    Ports: inputs ``u`` (shape (n,)) and ``v`` (scalar, same unit), output ``y``
    (spec of ``u``). This is how the L2 avatar's phase takes the assisted
    participant's place in what the group sees.

    Notes
    -----
    Bad data policy: stateless and element-wise, so a non-finite input element
    gives a non-finite output element on the same tick (as in NumPy) and
    nothing else; blocks with memory downstream decide how to treat it.
    """

    def __init__(self, index: int, *, period: float | None = None) -> None:
        super().__init__(index, period)
        self.add_input("v", Signal(shape=(), dtype=None, unit=None, wrapped=None))
        self.add_output("y", like="u")

    def setup(self) -> None:
        super().setup()
        shape = self.u.spec.shape
        problem = self.v.spec.with_(shape=shape).mismatch(self.u.spec)
        if problem:
            raise self._fail(f"v ({self.v.spec}) does not match the elements of u ({self.u.spec}): {problem}")

    batchable = True

    def output(self, k: int) -> None:
        y = self.y.value
        y[...] = self.u.value
        y[..., self.index] = self.v.value
