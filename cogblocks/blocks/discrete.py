"""Discrete-time dynamics and filters: unit delay, integrator, backward difference, low-pass, LTI systems."""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.signal

from cogblocks.blocks.specs import open_spec
from cogblocks.sim import ANY, Block
from cogblocks.sim.params import (
    finite_array,
    finite_number,
    one_of,
    positive_int,
    shape_arg,
    unit_arg,
    wrapped_arg,
)

__all__ = ["BackwardDifference", "DiscreteLTI", "Integrator", "LowPass", "UnitDelay", "sos_step"]


def sos_step(sos: Any, z: np.ndarray, x: Any, z_next: np.ndarray) -> Any:
    """One sample through second-order sections in transposed direct form II, as ``scipy.signal.sosfilt`` runs them.

    Parameters
    ----------
    sos : sequence of (b0, b1, b2, a0, a1, a2)
        The sections, ``a0 = 1``.
    z : ndarray, shape (n_sections, 2, ...)
        The state before the sample; not changed.
    x : float or ndarray
        The input sample (the trailing shape of ``z``).
    z_next : ndarray, like ``z``
        Receives the state after the sample.

    Returns
    -------
    float or ndarray
        The output sample.
    """
    for s, (b0, b1, b2, _, a1, a2) in enumerate(sos):
        y = b0 * x + z[s, 0]
        z_next[s, 0] = b1 * x - a1 * y + z[s, 1]
        z_next[s, 1] = b2 * x - a2 * y
        x = y
    return x


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
        self.add_input("u", open_spec(shape, None, None), feedthrough=False)
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
    gaps : {"hold", "repeat"}
        What a non-finite sample does (see below).

    Notes
    -----
    Bad data policy: with ``gaps="hold"`` (the default) a sample with NaN or inf
    is skipped: the output holds its last value and the filter state does not
    advance. With ``gaps="repeat"`` the filter runs on, fed with the last finite
    value of each element (so a gap filters exactly like a frozen sensor, which a
    block downstream can correct for, see ``Algorithm1Phase``); before any finite
    sample it holds.
    """

    def __init__(
        self, cutoff: float, order: int = 2, *, init: str = "first", gaps: str = "hold", period: float | None = None
    ) -> None:
        super().__init__(period=period)
        self.cutoff = finite_number(self, "cutoff", cutoff, low=0.0, low_open=True)
        self.order = positive_int(self, "order", order)
        self.init = one_of(self, "init", init, ("first", "zero"))
        self.gaps = one_of(self, "gaps", gaps, ("hold", "repeat"))
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
        if self.gaps == "repeat":  # only then: "hold" keeps a state a linearisation can perturb freely
            self.add_state("last", np.zeros(shape))  # the last finite value of each element
            self.add_state("seen", False)  # a wholly finite sample has arrived
            self.add_scratch("_last_next", np.zeros(shape))  # the tick's new `last`, committed in update()
        self.add_scratch("_z_next", np.zeros_like(self.z))  # the tick's new `z`, committed in update()
        extra = (slice(None), slice(None)) + (None,) * len(shape)
        self._zi_unit = self._zi_unit[extra]

    def output(self, k: int) -> None:
        x = self.u.value
        finite = np.isfinite(x)
        repeat = self.gaps == "repeat"
        if not np.all(finite):
            if not repeat or not self.seen:
                self._z_next[...] = self.z
                if repeat:
                    self._last_next[...] = self.last
                return
            x = np.where(finite, x, self.last)
        if repeat:
            self._last_next[...] = x
        if not self.primed:
            self.z = self._zi_unit * x
            self.primed = True
        self.y.value[...] = sos_step(self.sos, self.z, x, self._z_next)

    def update(self, k: int) -> None:
        self.z[...] = self._z_next
        if self.gaps == "repeat":
            self.last[...] = self._last_next
            self.seen = self.seen or bool(np.all(np.isfinite(self.u.value)))


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


class BackwardDifference(Block):
    """Backward-difference derivative: ``y[k] = (u[k] − u[k−1]) / dt``, ``y[0] = 0``.

    Ports: input ``u`` (any shape), output ``y`` (spec of ``u`` with ``/s`` appended to the unit,
    not wrapped).

    Notes
    -----
    Bad data policy: a non-finite sample gives a non-finite output and is not remembered; the next
    finite sample is differenced against the last finite one.
    """

    def __init__(self, *, period: float | None = None) -> None:
        super().__init__(period=period)
        self.add_input("u", ANY)
        self.add_output("y", like="u", unit=lambda unit: f"{unit}/s", wrapped=False)
        self.add_state("last", np.zeros(()))
        self.add_state("primed", False)

    def setup(self) -> None:
        self.add_state("last", np.zeros(self.u.spec.shape))

    def output(self, k: int) -> None:
        if self.primed:
            np.subtract(self.u.value, self.last, out=self.y.value)
            self.y.value /= self.dt
        else:
            self.y.value[...] = 0.0

    def update(self, k: int) -> None:
        if np.all(np.isfinite(self.u.value)):
            self.last[...] = self.u.value
            self.primed = True
