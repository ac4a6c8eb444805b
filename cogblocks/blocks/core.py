"""General-purpose blocks: sources, arithmetic, memory, filters, sinks, LTI systems.

Generic blocks (Gain, Sum, UnitDelay, ...) take the spec of whatever drives
them; give ``shape``/``unit`` explicitly only where a feedback loop of generic
blocks leaves nothing to infer from.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Mapping
from functools import partial
from typing import Any

import numpy as np
import scipy.signal

from cogblocks.sim import ANY, Block, Signal, SimulationError
from cogblocks.sim.params import (
    finite_array,
    finite_number,
    flag,
    one_of,
    positive_int,
    shape_arg,
    unit_arg,
    wrapped_arg,
)
from cogblocks.sim.signal import unit_product

__all__ = [
    "Constant",
    "Demux",
    "DiscreteLTI",
    "Function",
    "Gain",
    "Integrator",
    "LowPass",
    "Mux",
    "Playback",
    "Probe",
    "Saturation",
    "Select",
    "Substitute",
    "Sum",
    "UnitDelay",
]


def _open_spec(shape: Any, unit: str | None, wrapped: bool | None) -> Signal:
    return Signal(shape=shape, dtype=None, unit=unit, wrapped=wrapped)


class Constant(Block):
    """Output a constant value.

    Ports: output ``y`` (shape of ``value``).

    Parameters
    ----------
    value : array_like
        The value: finite numbers (a float64 signal), or bools or ints (kept as they are).
    unit : str
        Unit of the output.
    wrapped : bool
        Whether the value is an angle wrapped to one turn.

    Notes
    -----
    Bad data policy: no inputs; a non-finite value is refused when built.
    """

    def __init__(self, value: Any, *, unit: str = "1", wrapped: bool = False, period: float | None = None) -> None:
        super().__init__(period=period)
        given = np.asarray(value)
        # flags and counters stay what they are; everything else is a float signal
        dtype = given.dtype if given.dtype.kind in "bi" else np.float64
        arr = given if dtype != np.float64 else finite_array(self, "value", value)
        self.add_output("y", shape=arr.shape, dtype=dtype, unit=unit, wrapped=wrapped, initial=arr)


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


class _Memory(Block):
    """Shared set-up of blocks whose state has the size of their input (delay, integrator)."""

    def __init__(
        self,
        initial: Any,
        shape: Any,
        unit: str | None,
        wrapped: bool | None,
        period: float | None,
        derived: dict[str, Any],
    ) -> None:
        super().__init__(period=period)
        self._initial = finite_array(self, "initial", initial)
        shape = shape_arg(self, "shape", shape, optional=True)
        unit = unit_arg(self, "unit", unit, optional=True)
        wrapped = wrapped_arg(self, "wrapped", wrapped, optional=True)
        self.add_input("u", _open_spec(shape, None, None), feedthrough=False)
        if shape is not None:
            # explicit spec: what a feedback loop of generic blocks needs to compile
            self.add_output("y", shape=shape, unit=unit or "1", wrapped=bool(wrapped))
        else:
            overrides = dict(derived)
            if unit is not None:
                overrides["unit"] = unit
            if wrapped is not None:
                overrides["wrapped"] = wrapped
            self.add_output("y", like="u", **overrides)
        self.add_state("x", np.zeros(()))

    def setup(self) -> None:
        shape = self.y.spec.shape
        try:
            x0 = np.broadcast_to(self._initial, shape).astype(np.float64)
        except ValueError:
            raise self._fail(
                f"initial value of shape {self._initial.shape} does not fit the signal shape {shape}"
            ) from None
        self.add_state("x", x0.copy())
        self.y.initial = x0

    def output(self, k: int) -> None:
        self.y.value[...] = self.x


class UnitDelay(_Memory):
    """Delay the input by one step of the block: ``y[n] = u[n-1]``, ``y[0] = initial``.

    Ports: input ``u`` (not feedthrough, so it breaks algebraic loops), output ``y``
    (spec of ``u``).

    Parameters
    ----------
    initial : array_like
        Output before the first input arrives.
    shape, unit, wrapped : optional
        Spec of the signal; ``shape`` is needed only when a loop of generic blocks
        leaves it undetermined.

    Notes
    -----
    Bad data policy: a pure shift, so a non-finite input element comes out
    unchanged one step later and nothing else (the state is the last sample
    only, so nothing is poisoned); blocks with memory downstream decide how to
    treat it. Holding instead would hide a fault inside a feedback loop.
    """

    def __init__(
        self,
        initial: Any = 0.0,
        *,
        shape: Any = None,
        unit: str | None = None,
        wrapped: bool | None = None,
        period: float | None = None,
    ) -> None:
        super().__init__(initial, shape, unit, wrapped, period, {})

    def update(self, k: int) -> None:
        self.x[...] = self.u.value


def _integrated_unit(unit: str) -> str:
    if unit.endswith("/s"):
        return unit[:-2] or "1"
    return "s" if unit == "1" else f"{unit}*s"


class Integrator(_Memory):
    """Forward-Euler integrator: ``x[n+1] = x[n] + dt * u[n]``, ``y[n] = x[n]``.

    Ports: input ``u`` (not feedthrough), output ``y``. The output unit is the
    input unit times seconds (``"mm/s"`` gives ``"mm"``) unless ``unit`` is given.

    Parameters
    ----------
    initial : array_like
        Initial state.
    shape, unit : optional
        Spec of the output, when it cannot be inferred from the input.

    Notes
    -----
    Bad data policy: a sample with a non-finite element is skipped (the state
    holds), so one NaN never poisons the integral.
    """

    def __init__(
        self,
        initial: Any = 0.0,
        *,
        shape: Any = None,
        unit: str | None = None,
        period: float | None = None,
    ) -> None:
        super().__init__(initial, shape, unit, False, period, {"unit": _integrated_unit})

    def update(self, k: int) -> None:
        u = self.u.value
        if np.isfinite(u).all():
            self.x += self.dt * u


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


class LowPass(Block):
    """Butterworth low-pass filter, run sample by sample as second-order sections.

    The filter is designed by ``scipy.signal.butter(order, cutoff, fs=1/dt,
    output="sos")`` for the block's own step and run in transposed direct form
    II, exactly as ``scipy.signal.sosfilt`` does, one sample per tick.

    Ports: input ``u`` (any shape; each element filtered independently), output
    ``y`` (spec of ``u``).

    Parameters
    ----------
    cutoff : float
        Cut-off frequency in Hz, below the Nyquist frequency ``1 / (2 dt)``.
    order : int
        Filter order (2 by default).
    init : {"first", "zero"}
        ``"first"`` starts the filter in steady state at the first finite sample
        (no start-up transient); ``"zero"`` starts from rest.

    Notes
    -----
    Bad data policy: a sample with NaN or inf is skipped; the output holds its
    last value and the filter state does not advance.
    """

    def __init__(self, cutoff: float, order: int = 2, *, init: str = "first", period: float | None = None) -> None:
        super().__init__(period=period)
        self.cutoff = finite_number(self, "cutoff", cutoff, low=0.0, low_open=True)
        self.order = positive_int(self, "order", order)
        self.init = one_of(self, "init", init, ("first", "zero"))
        self.add_input("u", ANY)
        self.add_output("y", like="u")
        self.add_state("z", np.zeros(()))
        self.add_state("primed", False)

    def setup(self) -> None:
        nyquist = 0.5 / self.dt
        if self.cutoff >= nyquist:
            raise self._fail(
                f"cutoff {self.cutoff} Hz must be below the Nyquist frequency {nyquist:g} Hz of its step {self.dt} s"
            )
        self.sos = scipy.signal.butter(self.order, self.cutoff, fs=1.0 / self.dt, output="sos")
        self._zi_unit = scipy.signal.sosfilt_zi(self.sos)  # steady-state state for a unit input
        shape = self.u.spec.shape
        self.add_state("z", np.zeros((len(self.sos), 2) + shape))
        self.add_state("primed", self.init == "zero")
        self._z_next = np.zeros_like(self.z)
        extra = (slice(None), slice(None)) + (None,) * len(shape)
        self._zi_unit = self._zi_unit[extra]

    def output(self, k: int) -> None:
        x = self.u.value
        if not np.all(np.isfinite(x)):
            self._z_next[...] = self.z
            return
        if not self.primed:
            self.z = self._zi_unit * x
            self.primed = True
        z, z_next = self.z, self._z_next
        for s, (b0, b1, b2, _, a1, a2) in enumerate(self.sos):
            y = b0 * x + z[s, 0]
            z_next[s, 0] = b1 * x - a1 * y + z[s, 1]
            z_next[s, 1] = b2 * x - a2 * y
            x = y
        self.y.value[...] = x

    def update(self, k: int) -> None:
        self.z[...] = self._z_next


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


class Playback(Block):
    """Play an array, one row per step of the block.

    Ports: output ``y`` (shape of one row).

    Parameters
    ----------
    data : array_like
        Samples, shape ``(n, *shape)``.
    unit, wrapped : signal spec of the output.
    at_end : {"hold", "repeat", "zero", "error"}
        What to output after the last row.

    Notes
    -----
    Bad data policy: NaN rows are played as they are; Playback is how bad data
    gets into a diagram on purpose.
    """

    def __init__(
        self,
        data: Any,
        *,
        unit: str = "1",
        wrapped: bool = False,
        at_end: str = "hold",
        period: float | None = None,
    ) -> None:
        super().__init__(period=period)
        arr = np.array(data, dtype=np.float64)
        if arr.ndim < 1 or len(arr) == 0:
            raise ValueError(f"Playback: data must be an array with at least one row, got shape {arr.shape}")
        if np.isinf(arr).any():
            raise ValueError("Playback: data must not contain inf (NaN is allowed, to model missing samples)")
        self.data = arr
        self.at_end = one_of(self, "at_end", at_end, ("hold", "repeat", "zero", "error"))
        self.add_output("y", shape=arr.shape[1:], unit=unit, wrapped=wrapped)

    def output(self, k: int) -> None:
        i = k // self.every
        n = len(self.data)
        if i >= n:
            if self.at_end == "hold":
                i = n - 1
            elif self.at_end == "repeat":
                i %= n
            elif self.at_end == "zero":
                self.y.value[...] = 0.0
                return
            else:
                raise SimulationError(f"{self.name}: played all {n} samples; at_end='error'")
        self.y.value[...] = self.data[i]


class Probe(Block):
    """Mark a signal for recording; the Simulator records every Probe under its path.

    Ports: input ``u`` (any spec).

    Notes
    -----
    Bad data policy: records what it is given, NaN included; it has no output.
    """

    def __init__(self) -> None:
        super().__init__()
        self.add_input("u", ANY)


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

    def output(self, k: int) -> None:
        y = self.y.value
        for i, port in enumerate(self._ins):
            y[i] = port.value


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

    def output(self, k: int) -> None:
        u = self.u.value
        for i, port in enumerate(self._outs):
            port.value[...] = u[i]


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

    def output(self, k: int) -> None:
        self.y.value[...] = self.u.value[self.index]


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

    def output(self, k: int) -> None:
        y = self.y.value
        y[...] = self.u.value
        y[self.index] = self.v.value


class DiscreteLTI(Block):
    """A discrete-time LTI system from python-control: ``x+ = A x + B u``, ``y = C x + D u``.

    Ports: input ``u`` and output ``y``: scalars for a single-input or
    single-output system, vectors otherwise. ``u`` is feedthrough only when
    ``D`` is non-zero.

    Parameters
    ----------
    sys : control.StateSpace or control.TransferFunction
        A discrete-time system (``dt`` > 0 or ``True``). A positive ``dt`` must
        equal the block's step.
    x0 : array_like, optional
        Initial state (zeros by default).
    unit_in, unit_out : str
        Units of the ports.

    Notes
    -----
    Bad data policy: a sample with a non-finite element is skipped: the output
    holds and the state does not advance, so one NaN never poisons the state.
    """

    def __init__(
        self,
        sys: Any,
        x0: Any = None,
        *,
        unit_in: str = "1",
        unit_out: str = "1",
        period: float | None = None,
    ) -> None:
        import control

        super().__init__(period=period)
        if not isinstance(sys, (control.StateSpace, control.TransferFunction)):
            raise ValueError(
                f"DiscreteLTI: sys must be a control.StateSpace or TransferFunction, got {type(sys).__name__}"
            )
        if not sys.isdtime():
            raise ValueError(f"DiscreteLTI: sys must be discrete-time (dt > 0 or True), got dt={sys.dt!r}")
        ss = control.ss(sys)
        self.sys = ss
        self.A, self.B, self.C, self.D = (np.asarray(m, dtype=float) for m in (ss.A, ss.B, ss.C, ss.D))
        n, m, p = self.A.shape[0], self.B.shape[1], self.C.shape[0]
        x0 = np.zeros(n) if x0 is None else finite_array(self, "x0", x0, shape=(n,))
        unit_in, unit_out = unit_arg(self, "unit_in", unit_in), unit_arg(self, "unit_out", unit_out)
        self._scalar_in, self._scalar_out = m == 1, p == 1
        self.add_input("u", shape=() if m == 1 else (m,), unit=unit_in, feedthrough=bool(np.any(self.D)))
        self.add_output("y", shape=() if p == 1 else (p,), unit=unit_out)
        self.add_state("x", x0)

    def setup(self) -> None:
        sys_dt = self.sys.dt
        if sys_dt is not True and abs(float(sys_dt) - self.dt) > 1e-12:
            raise self._fail(f"the system's dt {sys_dt} s differs from the block's step {self.dt} s")

    def linear_feedthrough(self) -> dict[tuple[str, str], np.ndarray]:
        """``y = C x + D u``: the direct-feedthrough matrix is ``D``."""
        return {("y", "u"): self.D}

    def output(self, k: int) -> None:
        u = self.u.value.reshape(-1)
        if np.isfinite(u).all():
            y = self.C @ self.x + self.D @ u
            self.y.value[...] = y[0] if self._scalar_out else y

    def update(self, k: int) -> None:
        u = self.u.value.reshape(-1)
        if np.isfinite(u).all():
            self.x = self.A @ self.x + self.B @ u
