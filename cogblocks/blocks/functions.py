"""Static functions of the inputs: gain, sum, saturation and any Python function.

Generic blocks take the spec of whatever drives them; give ``shape``/``unit`` explicitly only where
a feedback loop of generic blocks leaves nothing to infer from."""

from __future__ import annotations

import inspect
from collections.abc import Callable, Mapping
from functools import partial
from typing import Any

import numpy as np

from cogblocks.sim import ANY, Block, Signal, SimulationError
from cogblocks.sim.params import (
    finite_array,
    finite_number,
    flag,
    unit_arg,
)
from cogblocks.sim.signal import unit_product

__all__ = ["Function", "Gain", "Saturation", "Sum"]


class Gain(Block):
    """Multiply the input by a gain: ``y = k * u``, or ``y = k @ u`` for a matrix gain.

    Ports: input ``u`` (any spec), output ``y`` (spec of ``u``, not wrapped; its
    unit times the gain's ``unit`` when that is given).

    Parameters
    ----------
    k : float or array_like
        Scalar or element-wise gain; with ``matrix=True`` a 2-D matrix.
    matrix : bool
        Treat ``k`` as a matrix (``y = k @ u``; ``u`` must be a vector).
    unit : str, optional
        The gain's own unit: the output's unit is the input's times it
        (``Gain(ki, unit="1/s")`` turns an error in ``"rad"`` into ``"rad/s"``).
        By default the output keeps the input's unit.

    Notes
    -----
    Bad data policy: stateless and element-wise, so a non-finite input element
    gives a non-finite output element on the same tick (as in NumPy) and
    nothing else; blocks with memory downstream decide how to treat it.
    """

    def __init__(self, k: Any, *, matrix: bool = False, unit: str | None = None, period: float | None = None) -> None:
        super().__init__(period=period)
        self.matrix = flag(self, "matrix", matrix)
        self.k = finite_array(self, "k", k, ndim=2 if self.matrix else None)
        self.unit = unit_arg(self, "unit", unit, optional=True)
        overrides: dict[str, Any] = {"wrapped": False}
        if self.unit is not None:
            try:
                unit_product("1", self.unit)  # refuse a unit that cannot be multiplied, now
            except ValueError as exc:
                raise ValueError(f"Gain: unit: {exc}") from None
            overrides["unit"] = partial(unit_product, b=self.unit)
        if matrix:
            overrides["shape"] = (self.k.shape[0],)
        self.add_input("u", ANY)
        self.add_output("y", like="u", **overrides)

    def setup(self) -> None:
        shape = self.u.spec.shape
        if self.matrix and shape != (self.k.shape[1],):
            raise self._fail(f"a {self.k.shape} matrix gain needs an input of shape ({self.k.shape[1]},), got {shape}")
        if not self.matrix and np.broadcast_shapes(self.k.shape, shape) != shape:
            raise self._fail(f"gain of shape {self.k.shape} does not broadcast to the input shape {shape}")

    def linear_feedthrough(self) -> dict[tuple[str, str], np.ndarray]:
        """``y = K u``: ``K`` is the matrix, or the element-wise gain on the diagonal."""
        if self.matrix:
            return {("y", "u"): self.k}
        return {("y", "u"): np.diag(np.broadcast_to(self.k, self.u.spec.shape).reshape(-1))}

    def output(self, k: int) -> None:
        # bad samples pass through (documented): no NumPy warning for inf * 0 or inf - inf
        with np.errstate(invalid="ignore", over="ignore"):
            if self.matrix:
                np.matmul(self.k, self.u.value, out=self.y.value)
            else:
                np.multiply(self.k, self.u.value, out=self.y.value)


class Sum(Block):
    """Add and subtract inputs: ``y = s0*u0 + s1*u1 + ...`` with signs from ``signs``.

    Ports: inputs ``u0``, ``u1``, ... (all of one shape and unit), output ``y``.

    Parameters
    ----------
    signs : str
        One ``+`` or ``-`` per input, e.g. ``"+-"`` for ``u0 - u1``.

    Notes
    -----
    Bad data policy: stateless and element-wise, so a non-finite input element
    gives a non-finite output element on the same tick (as in NumPy) and
    nothing else; blocks with memory downstream decide how to treat it.
    """

    def __init__(self, signs: str = "++", *, period: float | None = None) -> None:
        super().__init__(period=period)
        if not isinstance(signs, str) or not signs or set(signs) - {"+", "-"}:
            raise ValueError(f"Sum: signs must be a non-empty string of '+' and '-', got {signs!r}")
        self.signs = signs
        self._terms = [(self.add_input(f"u{i}", ANY), s == "+") for i, s in enumerate(signs)]
        self.add_output("y", like="u0", wrapped=False)

    def setup(self) -> None:
        first = self.u0.spec
        for port, _ in self._terms[1:]:
            if port.spec.shape != first.shape or port.spec.unit != first.unit:
                raise self._fail(f"all inputs must share shape and unit; u0 is {first}, {port.name} is {port.spec}")

    def linear_feedthrough(self) -> dict[tuple[str, str], np.ndarray]:
        """``y = sum(±u_i)``: plus or minus the identity per input."""
        eye = np.eye(self.y.value.size)
        return {("y", port.name): eye if positive else -eye for port, positive in self._terms}

    @np.errstate(invalid="ignore", over="ignore")  # bad samples pass through (documented), silently
    def output(self, k: int) -> None:
        y = self.y.value
        first, positive = self._terms[0]
        if positive:
            y[...] = first.value
        else:
            np.negative(first.value, out=y)
        for port, positive in self._terms[1:]:
            if positive:
                np.add(y, port.value, out=y)
            else:
                np.subtract(y, port.value, out=y)


class Saturation(Block):
    """Clip the input to ``[lower, upper]``.

    Ports: input ``u``, output ``y`` (spec of ``u``).

    Notes
    -----
    Bad data policy: stateless and element-wise; NaN passes through as NaN
    on the same tick, and ±inf is clipped to the bounds like any other value.
    """

    def __init__(self, lower: float, upper: float, *, period: float | None = None) -> None:
        super().__init__(period=period)
        self.lower = finite_number(self, "lower", lower)
        self.upper = finite_number(self, "upper", upper, low=self.lower)
        self.add_input("u", ANY)
        self.add_output("y", like="u")

    def output(self, k: int) -> None:
        np.clip(self.u.value, self.lower, self.upper, out=self.y.value)


class Function(Block):
    """Wrap a Python callable as a stateless block with declared ports.

    The callable receives the inputs as keyword arguments (scalars as ``float``,
    others as arrays) and, if it has a parameter named ``t``, the time in
    seconds. It returns the output value, or a tuple (in declared order) or dict
    for several outputs.

    Parameters
    ----------
    fn : callable
        The function.
    inputs : mapping of str to Signal
        Input ports and their specs.
    outputs : Signal or mapping of str to Signal
        Output spec (a single output named ``y``) or output ports and specs.
    feedthrough : bool
        Whether the outputs depend on the inputs of the same tick (default True).

    Notes
    -----
    Bad data policy: the callable's own. The block outputs exactly what the
    callable returns and adds no check, so a callable that must not emit NaN
    has to test its inputs itself.

    Examples
    --------
    >>> from cogblocks.sim import Signal
    >>> f = Function(lambda a, b: a * b, inputs={"a": Signal(), "b": Signal()}, outputs=Signal())
    """

    def __init__(
        self,
        fn: Callable[..., Any],
        inputs: Mapping[str, Signal],
        outputs: Signal | Mapping[str, Signal],
        *,
        feedthrough: bool = True,
        period: float | None = None,
    ) -> None:
        super().__init__(period=period)
        if not callable(fn):
            raise ValueError(f"Function: fn must be callable, got {fn!r}")
        if not isinstance(inputs, Mapping):
            raise ValueError(f"Function: inputs must be a mapping of port name to Signal, got {inputs!r}")
        if not isinstance(outputs, (Signal, Mapping)):
            raise ValueError(f"Function: outputs must be a Signal or a mapping of port name to Signal, got {outputs!r}")
        feedthrough = flag(self, "feedthrough", feedthrough)
        self.fn = fn
        for name, spec in inputs.items():
            self.add_input(name, spec, feedthrough=feedthrough)
        outs = {"y": outputs} if isinstance(outputs, Signal) else dict(outputs)
        if not outs:
            raise ValueError("Function: outputs must declare at least one output")
        self._outs = [self.add_output(name, spec) for name, spec in outs.items()]
        try:
            params = inspect.signature(fn).parameters
        except (TypeError, ValueError):
            params = {}
        self._pass_time = "t" in params and "t" not in self._inputs
        self._ins = list(self._inputs.values())

    def output(self, k: int) -> None:
        kwargs = {p.name: (float(p.value) if p.value.ndim == 0 else p.value) for p in self._ins}
        if self._pass_time:
            kwargs["t"] = k * (self.dt / self.every)
        result = self.fn(**kwargs)
        if len(self._outs) == 1:
            values = (result,)
        elif isinstance(result, Mapping):
            values = tuple(result[p.name] for p in self._outs)
        else:
            values = tuple(result)
        for port, value in zip(self._outs, values, strict=True):
            try:
                port.value[...] = value
            except (ValueError, TypeError) as exc:
                raise SimulationError(
                    f"{self.name}: the function returned {np.shape(value)} for output {port.name!r} of shape "
                    f"{port.value.shape}"
                ) from exc
