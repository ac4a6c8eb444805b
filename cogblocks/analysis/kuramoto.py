"""Linearisation of a Kuramoto group about its phase-locked state: Jacobian, locking search, stability."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Any

import control
import numpy as np
import scipy.linalg
import scipy.optimize

from cogblocks.sim.params import finite_array, finite_number
from cogblocks.sim.timing import BASE_STEP
from cogblocks.sync import ring_adjacency

__all__ = ["KuramotoLinearization", "kuramoto_jacobian", "kuramoto_linearization"]

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
        as :class:`~cogblocks.sync.KuramotoGroup` integrates):
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
    dt: float = BASE_STEP,
) -> KuramotoLinearization:
    """Find a stable phase-locked state of a Kuramoto network and linearise around it.

    Parameters
    ----------
    omega : array_like
        Natural frequencies in rad/s (N >= 2).
    gain : float
        Coupling gain (> 0), multiplying ``Σ_j a_ij sin(θ_j − θ_i)`` as in
        :class:`~cogblocks.sync.KuramotoGroup`.
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
