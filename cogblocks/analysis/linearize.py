"""Linearisation: phase-locked Kuramoto networks, and any compiled diagram of smooth blocks.

Two tools:

* :func:`kuramoto_linearization` finds a phase-locked state of the Kuramoto network
  ``θ̇_i = ω_i + gain Σ_j a_ij sin(θ_j − θ_i)`` (the model of
  :class:`~cogblocks.blocks.KuramotoGroup`), its Jacobian, eigenvalues and local
  convergence rate, and state-space models of the continuous and forward-Euler
  dynamics around it;
* :func:`linearize` gives the discrete-time linearisation of the one-tick map of any
  compiled diagram, by central finite differences.
"""

from __future__ import annotations

import copy
import itertools
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import control
import numpy as np
import scipy.linalg
import scipy.optimize

from cogblocks.blocks.group import ring_adjacency
from cogblocks.sim import Block, CompiledDiagram, Diagram
from cogblocks.sim.params import finite_array, finite_number

__all__ = ["KuramotoLinearization", "kuramoto_jacobian", "kuramoto_linearization", "linearize"]

TWO_PI = 2.0 * math.pi
# Largest network whose cuts are all enumerated for the necessary locking condition.
_MAX_CUT_NODES = 16
# Points on which the ring's one-parameter family of candidate states is scanned for roots.
_RING_GRID = 2001
# Random starting points of the Newton search on graphs other than rings.
_RANDOM_STARTS = 16
# Residual below which a candidate solves the locking equations (rad/s).
_LOCK_TOL = 1e-9
# Real part below which an eigenvalue counts as strictly negative (1/s).
_STABLE_TOL = 1e-9


def _wrap_pi(x: np.ndarray) -> np.ndarray:
    """Wrap angles to (−π, π]."""
    return math.pi - np.mod(math.pi - x, TWO_PI)


# -- Kuramoto networks --------------------------------------------------------------------------


def kuramoto_jacobian(theta: Any, gain: float, adjacency: Any) -> np.ndarray:
    """Jacobian of ``θ ↦ ω + gain Σ_j a_ij sin(θ_j − θ_i)`` at ``theta``.

    ``J_ij = gain a_ij cos(θ_j − θ_i)`` for ``j ≠ i`` and ``J_ii = −Σ_{j≠i} J_ij``, so
    every row sums to zero: a common rotation of all phases changes nothing.
    """
    theta = np.asarray(theta, dtype=float)
    a = np.asarray(adjacency, dtype=float)
    jac = gain * a * np.cos(theta[None, :] - theta[:, None])
    np.fill_diagonal(jac, 0.0)
    jac[np.diag_indices_from(jac)] = -jac.sum(axis=1)
    return jac


@dataclass(frozen=True, eq=False)
class KuramotoLinearization:
    """A phase-locked state of a Kuramoto network and the linear dynamics around it.

    Attributes
    ----------
    omega : ndarray
        Natural frequencies (rad/s).
    gain : float
        Coupling gain.
    adjacency : ndarray
        Coupling graph, ``a_ij = 1`` when i sees j.
    dt : float
        Step of the discrete model.
    phases : ndarray or None
        Locked phase offsets ``θ_i − θ_0`` in (−π, π], or None when no locked state
        was found (see ``message``).
    frequency : float or None
        Common frequency Ω of the locked state (rad/s): ``mean(ω)`` on a symmetric graph.
    stable : bool
        Whether the locked state attracts nearby phases (up to a common rotation).
    message : str
        What was found, or why there is no locked state.
    jacobian : ndarray or None
        ``J`` of :func:`kuramoto_jacobian` at the locked state.
    eigenvalues : ndarray or None
        Eigenvalues of J, by decreasing real part; the first is the exact 0 of the
        rotation symmetry (eigenvector ``(1, …, 1)``), the others those of J on the
        phase differences.
    rate : float or None
        Largest real part among the eigenvalues other than the rotation's 0:
        negative for a stable state, perturbations then decay like ``exp(rate t)``.
    continuous, discrete : control.StateSpace or None
        Linearisations in the frame rotating with the locked state: states and
        outputs ``theta[i]`` (phase deviations), inputs ``omega[i]`` (frequency
        deviations). ``continuous``: ``ẋ = J x + u``; ``discrete`` (forward Euler,
        as :class:`~cogblocks.blocks.KuramotoGroup` integrates):
        ``x+ = (I + dt J) x + dt u``.
    """

    omega: np.ndarray
    gain: float
    adjacency: np.ndarray
    dt: float
    phases: np.ndarray | None
    frequency: float | None
    stable: bool
    message: str
    jacobian: np.ndarray | None = None
    eigenvalues: np.ndarray | None = None
    rate: float | None = None
    continuous: control.StateSpace | None = None
    discrete: control.StateSpace | None = None

    @property
    def locked(self) -> bool:
        """True when the network has a stable phase-locked state (it locks)."""
        return self.phases is not None and self.stable

    def __str__(self) -> str:
        lines = [self.message]
        if self.phases is not None:
            lines.append(f"  phases θ_i − θ_0 (rad): {np.array2string(self.phases, precision=4)}")
            lines.append(f"  eigenvalues of J (1/s): {np.array2string(self.eigenvalues, precision=4)}")
        return "\n".join(lines)


def _locking_residual(omega: np.ndarray, gain: float, a: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Locking equations in z = (θ_1 … θ_{N−1}, Ω), θ_0 = 0: ω_i + coupling_i − Ω."""
    theta = np.concatenate([[0.0], z[:-1]])
    return omega + gain * (a * np.sin(theta[None, :] - theta[:, None])).sum(axis=1) - z[-1]


def _locking_jacobian(omega: np.ndarray, gain: float, a: np.ndarray, z: np.ndarray) -> np.ndarray:
    jac = kuramoto_jacobian(np.concatenate([[0.0], z[:-1]]), gain, a)
    return np.column_stack([jac[:, 1:], -np.ones(len(omega))])


def _polish(omega: np.ndarray, gain: float, a: np.ndarray, theta: np.ndarray) -> np.ndarray | None:
    """Newton from ``theta`` (any offset); the locked phases relative to θ_0, or None."""
    theta = theta - theta[0]
    coupling = gain * (a * np.sin(theta[None, :] - theta[:, None])).sum(axis=1)
    z0 = np.concatenate([theta[1:], [np.mean(omega + coupling)]])
    sol = scipy.optimize.root(
        lambda z: _locking_residual(omega, gain, a, z),
        z0,
        jac=lambda z: _locking_jacobian(omega, gain, a, z),
        method="hybr",
        options={"xtol": 1e-14},
    )
    if not np.all(np.isfinite(sol.x)) or np.abs(_locking_residual(omega, gain, a, sol.x)).max() > _LOCK_TOL:
        return None
    return np.concatenate([[0.0], _wrap_pi(sol.x[:-1])])


def _reduced_eigenvalues(jac: np.ndarray) -> np.ndarray:
    """Eigenvalues of J on the phase differences (J without the rotation's 0)."""
    basis = scipy.linalg.null_space(np.ones((1, len(jac))))  # orthonormal basis of 1^⊥
    reduced = basis.T @ jac @ basis
    if np.allclose(jac, jac.T):
        return np.sort(np.linalg.eigvalsh((reduced + reduced.T) / 2))[::-1]
    eig = np.linalg.eigvals(reduced)
    return eig[np.argsort(-eig.real)]


def _eig_and_rate(jac: np.ndarray) -> tuple[float, np.ndarray]:
    reduced = _reduced_eigenvalues(jac)
    return float(reduced.real.max()), np.concatenate([np.zeros(1, dtype=reduced.dtype), reduced])


def _worst_cut(deviation: np.ndarray, gain: float, a: np.ndarray) -> tuple[float, list[int]]:
    """max over node sets S of |Σ_S (ω_i − Ω)| / (gain · links from S to the rest), and the set.

    On a symmetric graph the couplings inside S cancel in the sum of S's locking
    equations, so a ratio above 1 proves that no locked state exists.
    """
    n = len(deviation)
    if n <= _MAX_CUT_NODES:
        # node 0 outside S: S and its complement give the same cut
        masks = np.array(list(itertools.product([False, True], repeat=n - 1)))[1:]
        masks = np.column_stack([np.zeros(len(masks), dtype=bool), masks])
    else:
        masks = np.eye(n, dtype=bool)
    flow = np.abs(masks @ deviation)
    links = np.einsum("si,ij,sj->s", masks.astype(float), a, (~masks).astype(float))
    # a set with no link to the rest (a disconnected graph) locks only if its deviations cancel
    unlinked = np.where(flow > 1e-12 * (1.0 + np.abs(deviation).sum()), np.inf, 0.0)
    ratio = np.divide(flow, gain * links, out=unlinked, where=links > 0)
    worst = int(np.argmax(ratio))
    return float(ratio[worst]), [int(i) for i in np.flatnonzero(masks[worst])]


def _ring_candidates(deviation: np.ndarray, gain: float) -> list[np.ndarray]:
    """Every locked state of a ring with at most one link beyond ±π/2.

    On the ring ``K sin(θ_{i+1} − θ_i) = c − T_i`` with ``T_i = Σ_{k=1..i}(ω_k − Ω)``:
    one free constant c. Each link difference is ``asin`` or ``±π − asin`` of that,
    and the differences must add up to a whole number of turns. A stable state has
    at most one link beyond ±π/2 (two such links form a cut of negative weight,
    along which the state is unstable), so these are all the candidates for one.
    """
    n = len(deviation)
    t = np.concatenate([[0.0], np.cumsum(deviation[1:])])
    lo, hi = t.max() - gain, t.min() + gain
    if lo > hi:
        return []
    grid = np.linspace(lo, hi, _RING_GRID)

    def differences(c: float | np.ndarray, far: int | None) -> np.ndarray:
        x = np.clip((np.asarray(c)[..., None] - t) / gain, -1.0, 1.0)
        delta = np.arcsin(x)
        if far is not None:
            delta[..., far] = np.where(x[..., far] >= 0, math.pi, -math.pi) - delta[..., far]
        return delta

    found = []
    for far in [None, *range(n)]:
        total = differences(grid, far).sum(axis=-1)
        for turns in range(-(n // 2), n // 2 + 1):
            gap = total - TWO_PI * turns
            for i in np.flatnonzero(np.sign(gap[:-1]) * np.sign(gap[1:]) <= 0):
                if gap[i] == gap[i + 1] == 0.0:
                    continue
                c = scipy.optimize.brentq(
                    lambda c, far=far, turns=turns: differences(c, far).sum() - TWO_PI * turns, grid[i], grid[i + 1]
                )
                found.append(np.concatenate([[0.0], np.cumsum(differences(c, far)[:-1])]))
    return found


def _search_candidates(n: int) -> list[np.ndarray]:
    """Starting points of the Newton search on a general graph: in phase, then random."""
    rng = np.random.default_rng(0)
    return [np.zeros(n)] + [rng.uniform(0.0, TWO_PI, n) for _ in range(_RANDOM_STARTS)]


def kuramoto_linearization(
    omega: Any,
    gain: float,
    adjacency: Any = "ring",
    *,
    dt: float = 0.01,
) -> KuramotoLinearization:
    """Find a stable phase-locked state of a Kuramoto network and linearise around it.

    Parameters
    ----------
    omega : array_like
        Natural frequencies in rad/s (N >= 2).
    gain : float
        Coupling gain (> 0), multiplying ``Σ_j a_ij sin(θ_j − θ_i)`` as in
        :class:`~cogblocks.blocks.KuramotoGroup`.
    adjacency : "ring" or array_like
        Coupling graph, a ring by default.
    dt : float
        Step of the forward-Euler model.

    Returns
    -------
    KuramotoLinearization
        The locked state, its Jacobian, eigenvalues, rate and state-space models;
        or, when there is none, ``phases=None`` and a ``message`` saying why.

    Notes
    -----
    A locked state has every ``θ̇_i`` equal to a common Ω. The search:

    1. On a symmetric graph, a set S of oscillators whose frequency deviations
       ``Σ_S (ω_i − Ω)`` exceed ``gain`` times its links to the rest cannot lock:
       every cut is checked (single nodes only above 16 oscillators). This
       proves Groups 1 and 2 of Table 2 never lock.
    2. On a ring (N >= 3), every candidate for a stable locked state is
       enumerated exactly (see ``_ring_candidates``), so "no stable locked state"
       is a proof, not a failure to find one.
    3. On other graphs, Newton from the in-phase state and from random phases:
       "none found" is then not a proof.

    Candidates are refined by Newton; among the stable ones the most synchronised
    (largest order parameter) is returned, otherwise the least unstable one.
    """
    omega = finite_array("kuramoto_linearization", "omega", omega, ndim=1)
    n = len(omega)
    if n < 2:
        raise ValueError(f"kuramoto_linearization: omega must hold at least 2 frequencies, got {n}")
    gain = finite_number("kuramoto_linearization", "gain", gain, low=0.0, low_open=True)
    dt = finite_number("kuramoto_linearization", "dt", dt, low=0.0, low_open=True)
    is_ring = isinstance(adjacency, str)
    if is_ring and adjacency != "ring":
        raise ValueError(f"kuramoto_linearization: adjacency must be 'ring' or an {n}x{n} matrix, got {adjacency!r}")
    a = ring_adjacency(n) if is_ring else finite_array("kuramoto_linearization", "adjacency", adjacency, shape=(n, n))
    is_ring = n >= 3 and np.array_equal(a, ring_adjacency(n))
    symmetric = np.array_equal(a, a.T)
    base = dict(omega=omega, gain=gain, adjacency=a, dt=dt)

    if symmetric:
        ratio, drifting = _worst_cut(omega - omega.mean(), gain, a)
        if ratio > 1.0:
            return KuramotoLinearization(
                **base,
                phases=None,
                frequency=None,
                stable=False,
                message=(
                    f"no phase-locked state exists: oscillators {drifting} deviate from the mean frequency by "
                    f"{ratio:.3g} times what their links to the others can pull (gain × links); locking needs "
                    f"gain >= {ratio * gain:.4g}"
                ),
            )

    starts = _ring_candidates(omega - omega.mean(), gain) if is_ring else _search_candidates(n)
    states: list[tuple[np.ndarray, float, np.ndarray]] = []
    for start in starts:
        phases = _polish(omega, gain, a, start)
        if phases is None or any(np.abs(_wrap_pi(phases - p)).max() < 1e-6 for p, _, _ in states):
            continue
        states.append((phases, *_eig_and_rate(kuramoto_jacobian(phases, gain, a))))
    stable = [s for s in states if s[1] < -_STABLE_TOL]
    how = (
        "every candidate for one enumerated on the ring"
        if is_ring
        else f"Newton from {len(starts)} starting points (not a proof)"
    )
    if not states:
        return KuramotoLinearization(
            **base, phases=None, frequency=None, stable=False, message=f"no stable phase-locked state ({how})"
        )
    if stable:
        phases, rate, eig = max(stable, key=lambda s: abs(np.exp(1j * s[0]).mean()))
    else:
        phases, rate, eig = max(states, key=lambda s: -s[1])

    jac = kuramoto_jacobian(phases, gain, a)
    frequency = float(np.mean(omega + gain * (a * np.sin(phases[None, :] - phases[:, None])).sum(axis=1)))
    names = dict(
        states=[f"theta[{i}]" for i in range(n)],
        inputs=[f"omega[{i}]" for i in range(n)],
        outputs=[f"theta[{i}]" for i in range(n)],
    )
    eye = np.eye(n)
    if stable:
        message = (
            f"phase-locked at Ω = {frequency:.6g} rad/s, r = {abs(np.exp(1j * phases).mean()):.4f}; local "
            f"convergence rate {rate:.4g} 1/s (time constant {-1.0 / rate:.3g} s)"
        )
        if len(stable) > 1:
            message += f"; {len(stable)} stable locked states, the most synchronised shown"
    else:
        message = (
            f"no stable phase-locked state ({how}); the least unstable locked state found has rate "
            f"{rate:.4g} 1/s, so the network drifts"
        )
    return KuramotoLinearization(
        **base,
        phases=phases,
        frequency=frequency,
        stable=bool(stable),
        message=message,
        jacobian=jac,
        eigenvalues=eig,
        rate=rate,
        continuous=control.ss(jac, eye, eye, np.zeros((n, n)), **names, name="kuramoto"),
        discrete=control.ss(eye + dt * jac, dt * eye, eye, np.zeros((n, n)), dt, **names, name="kuramoto_euler"),
    )


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
        The diagram (its last compiled plan, compiled at 10 ms if it has none) or plan.
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
    compiled = system if isinstance(system, CompiledDiagram) else system.compiled
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
