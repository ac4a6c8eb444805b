"""Linearisation: phase-locked Kuramoto networks, and any compiled diagram of smooth blocks.

Two tools:

* :func:`kuramoto_linearization` finds a phase-locked state of the Kuramoto network
  ``θ̇_i = ω_i + gain Σ_j a_ij sin(θ_j − θ_i)`` (the model of
  :class:`~cogblocks.sync.KuramotoGroup`), its Jacobian, eigenvalues and local
  convergence rate, and state-space models of the continuous and forward-Euler
  dynamics around it;
* :func:`linearize` gives the discrete-time linearisation of the one-tick map of any
  compiled diagram, by central finite differences."""

from __future__ import annotations

import copy
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import control
import numpy as np

from cogblocks.analysis.kuramoto import TWO_PI, _wrap_pi
from cogblocks.sim import BASE_STEP, Block, CompiledDiagram, Diagram

__all__ = ["linearize"]

# -- Any diagram --------------------------------------------------------------------------------


@dataclass
class _Var:
    """One declared float state of a leaf block, as a slice of the state vector x."""

    path: str
    name: str
    shape: tuple[int, ...]
    is_array: bool
    wrapped: bool
    start: int

    @property
    def stop(self) -> int:
        return self.start + int(np.prod(self.shape, dtype=int))

    def labels(self) -> list[str]:
        return _labels(f"{self.path}.{self.name}", self.shape)


def _labels(base: str, shape: tuple[int, ...]) -> list[str]:
    if shape == ():
        return [base]
    return [f"{base}[{','.join(map(str, idx))}]" for idx in np.ndindex(*shape)]


def _is_float_state(value: Any) -> bool:
    if isinstance(value, np.ndarray):
        return value.dtype.kind == "f"
    return isinstance(value, (float, np.floating))


def _copied_by_wrapped_output(block: Block, name: str, k: int) -> bool:
    """Whether a wrapped output of ``block`` is a copy of state ``name`` (then the state is an angle too).

    Two distinct test angles are written into the state and ``block.output`` is run:
    the output must reproduce both exactly. The caller restores the block afterwards.
    """
    value = getattr(block, name)
    shape = np.shape(value)
    ports = [p for p in block.outputs.values() if p.spec.wrapped and p.value.shape == shape]
    for port in ports:
        copies = True
        for first in (1.0, 4.0):
            probe = np.mod(first + 0.1 * np.arange(int(np.prod(shape, dtype=int))).reshape(shape), TWO_PI)
            setattr(block, name, probe.copy() if isinstance(value, np.ndarray) else float(probe))
            block.output(k)
            copies = copies and np.array_equal(port.value, probe)
        if copies:
            return True
    return False


def linearize(
    system: Diagram | CompiledDiagram,
    operating_point: Mapping[str, Any] | None = None,
    *,
    inputs: Mapping[str, Any] | None = None,
    eps: float = 1e-6,
    wrapped_states: Iterable[str] | None = None,
    hold: Iterable[str] = (),
) -> control.StateSpace:
    """Discrete-time linearisation of one tick of a compiled diagram, by central differences.

    ``x[k+1] ≈ A x[k] + B u[k]``, ``y[k] ≈ C x[k] + D u[k]`` for deviations from the
    operating point, with the diagram's base step as ``dt``.

    Parameters
    ----------
    system : Diagram or CompiledDiagram
        The diagram (its last compiled plan, compiled at the base step if it has none) or plan.
    operating_point : mapping, optional
        A snapshot from ``state_dict()`` of the same plan; None for its current state.
        Its tick ``k`` is the tick linearised (it matters for time-varying sources
        such as :class:`~cogblocks.blocks.Playback`).
    inputs : mapping of str to array_like, optional
        Values of the top-level diagram inputs at the operating point; those not
        given are taken from the snapshot.
    eps : float
        Finite-difference step, relative for values beyond 1 in magnitude:
        ``h = eps · max(1, |x_j|)``.
    wrapped_states : iterable of str, optional
        ``"block.path.state"`` names of the states that are angles wrapped to
        [0, 2π). By default a float state is taken as wrapped when a wrapped output
        of its block is an exact copy of it (the block's ``output`` is run with two
        test angles in the state); give the list when a block keeps an angle it
        does not output as is. An empty list means no wrapped state.
    hold : iterable of str
        ``"block.path.state"`` names of states kept at their operating-point value
        at the start of every evaluated tick and left out of x. Needed for every
        state that is not a float or float array (random generators, booleans,
        integer counters): each evaluation then sees the same random draw or
        flag, and the result is the linearisation for that draw or mode.

    Returns
    -------
    control.StateSpace
        Discrete-time system with ``dt`` the base step. States: every leaf block's
        declared float state, flattened (C order), blocks in the plan's execution
        order (``compiled.blocks``) and each block's states in declaration order;
        labels ``"path.state"`` or ``"path.state[i]"``. Inputs: the top-level
        diagram inputs (``compiled.input_names`` order), flattened; outputs: the
        top-level diagram outputs, flattened, labelled the same way.

    Raises
    ------
    ValueError
        For a state that is neither a float nor held (naming the block and the
        state), a name in ``wrapped_states`` or ``hold`` that is no state, or a
        multirate diagram (a block with a period longer than the base step makes
        the one-tick map depend on the tick and its held outputs part of the state).

    Notes
    -----
    Differences of wrapped states and of outputs whose spec is ``wrapped`` are
    wrapped to (−π, π], and perturbed wrapped values are wrapped back to
    [0, 2π) before the tick is run, so operating points next to 0 or 2π are fine.
    Only the step from the operating point is evaluated: a block that is not
    differentiable there (a saturation at its limit, a branch on a threshold)
    gives the average of its one-sided slopes. The plan's state is restored
    exactly afterwards.
    """
    if not isinstance(system, (Diagram, CompiledDiagram)):
        raise TypeError(f"linearize needs a Diagram or CompiledDiagram, got {type(system).__name__}")
    if isinstance(system, CompiledDiagram):
        compiled = system
    else:  # a diagram's last plan; one that was never compiled is compiled at the base step, as documented
        compiled = system.plan if system.plan is not None else system.compile(BASE_STEP)
    if not (isinstance(eps, (int, float)) and math.isfinite(eps) and eps > 0):
        raise ValueError(f"linearize: eps must be a positive number, got {eps!r}")
    slow = [path for path, block in compiled.blocks.items() if block.every > 1]
    if slow:
        raise ValueError(
            f"linearize: blocks {slow} run slower than the base step; the one-tick map of a multirate diagram "
            "depends on the tick and on held outputs, which this linearisation does not cover"
        )
    saved = compiled.state_dict()
    point = copy.deepcopy(saved if operating_point is None else operating_point)
    for name, value in (inputs or {}).items():
        if name not in point["inputs"]:
            raise ValueError(f"linearize: the diagram has no input {name!r}; its inputs are {compiled.input_names}")
        point["inputs"][name] = np.broadcast_to(np.asarray(value, dtype=float), point["inputs"][name].shape).copy()
    held = set(hold)
    wrapped = None if wrapped_states is None else set(wrapped_states)
    declared = {f"{path}.{name}" for path, block in compiled.blocks.items() for name in block.state_names}
    for label, names in (("hold", held), ("wrapped_states", wrapped or set())):
        unknown = sorted(names - declared)
        if unknown:
            raise ValueError(f"linearize: {label} names no state {unknown}; the states are {sorted(declared)}")
    try:
        compiled.load_state_dict(point)
        variables = _state_variables(compiled, point, held, wrapped)
        return _finite_differences(compiled, point, variables, float(eps))
    finally:
        compiled.load_state_dict(saved)


def _state_variables(
    compiled: CompiledDiagram, point: Mapping[str, Any], held: set[str], wrapped: set[str] | None
) -> list[_Var]:
    variables: list[_Var] = []
    start = 0
    for path, block in compiled.blocks.items():
        for name in block.state_names:
            full = f"{path}.{name}"
            if full in held:
                continue
            value = getattr(block, name)  # the live object: a snapshot keeps a generator as a dict
            if not _is_float_state(value):
                dtype = f" ({value.dtype})" if isinstance(value, np.ndarray) else ""
                raise ValueError(
                    f"linearize: block {path!r} has state {name!r} of type {type(value).__name__}{dtype}, "
                    f"not a float; pass hold=[{full!r}] to keep it at its operating-point value"
                )
            if wrapped is None:
                is_wrapped = _copied_by_wrapped_output(block, name, int(point["k"]))
                compiled.load_state_dict(point)
            else:
                is_wrapped = full in wrapped
            var = _Var(path, name, np.shape(value), isinstance(value, np.ndarray), is_wrapped, start)
            variables.append(var)
            start = var.stop
    return variables


def _flat(values: Iterable[Any]) -> np.ndarray:
    return np.concatenate([np.ravel(v).astype(float) for v in values] or [np.zeros(0)])


def _finite_differences(
    compiled: CompiledDiagram, point: Mapping[str, Any], variables: list[_Var], eps: float
) -> control.StateSpace:
    x0 = _flat(point["blocks"][v.path]["state"][v.name] for v in variables)
    x_wrapped = np.concatenate([np.full(v.stop - v.start, v.wrapped) for v in variables] or [np.zeros(0, bool)])
    in_names, out_names = compiled.input_names, compiled.output_names
    in_shapes = [point["inputs"][name].shape for name in in_names]
    u0 = _flat(point["inputs"][name] for name in in_names)
    u_wrapped = np.concatenate(
        [
            np.full(int(np.prod(shape, dtype=int)), bool(compiled.diagram.inputs[name].spec.wrapped))
            for name, shape in zip(in_names, in_shapes, strict=True)
        ]
        or [np.zeros(0, bool)]
    )

    def tick(x: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, dict[str, Any]]:
        compiled.load_state_dict(point)
        for v in variables:
            value = x[v.start : v.stop].reshape(v.shape)
            setattr(compiled.blocks[v.path], v.name, value.copy() if v.is_array else float(value))
        sizes = np.cumsum([0] + [int(np.prod(shape, dtype=int)) for shape in in_shapes])
        feed = {
            name: u[a:b].reshape(shape)
            for name, shape, a, b in zip(in_names, in_shapes, sizes[:-1], sizes[1:], strict=True)
        }
        out = compiled.step(**feed)
        return _flat(getattr(compiled.blocks[v.path], v.name) for v in variables), out

    _, out0 = tick(x0, u0)
    out_shapes = [np.shape(out0[name]) for name in out_names]
    y_wrapped = np.concatenate(
        [
            np.full(int(np.prod(shape, dtype=int)), bool(compiled.diagram.outputs[name].spec.wrapped))
            for name, shape in zip(out_names, out_shapes, strict=True)
        ]
        or [np.zeros(0, bool)]
    )
    rows_wrapped = np.concatenate([x_wrapped, y_wrapped])

    def image(x: np.ndarray, u: np.ndarray) -> np.ndarray:
        x_next, out = tick(x, u)
        return np.concatenate([x_next, _flat(out[name] for name in out_names)])

    def column(j: int, of_state: bool) -> np.ndarray:
        base, wrap = (x0, x_wrapped) if of_state else (u0, u_wrapped)
        h = eps * max(1.0, abs(base[j]))
        images = []
        for sign in (1.0, -1.0):
            moved = base.copy()
            moved[j] += sign * h
            if wrap[j]:
                moved[j] %= TWO_PI
            images.append(image(moved, u0) if of_state else image(x0, moved))
        diff = images[0] - images[1]
        diff[rows_wrapped] = _wrap_pi(diff[rows_wrapped])
        return diff / (2.0 * h)

    n, m = len(x0), len(u0)
    rows = n + len(y_wrapped)
    by_state = np.column_stack([column(j, True) for j in range(n)]) if n else np.zeros((rows, 0))
    by_input = np.column_stack([column(j, False) for j in range(m)]) if m else np.zeros((rows, 0))
    return control.ss(
        by_state[:n],
        by_input[:n],
        by_state[n:],
        by_input[n:],
        compiled.dt,
        states=[label for v in variables for label in v.labels()],
        inputs=[label for name, shape in zip(in_names, in_shapes, strict=True) for label in _labels(name, shape)],
        outputs=[label for name, shape in zip(out_names, out_shapes, strict=True) for label in _labels(name, shape)],
        name="linearized",
    )
