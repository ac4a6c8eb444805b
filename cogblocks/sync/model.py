"""The group model the L3 policies plan with: Kuramoto group, virtual oscillator and blender, batched in NumPy."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
import scipy.sparse as sp

from cogblocks.blocks.angles import wrap_pi
from cogblocks.data.groups import SyncGroup
from cogblocks.sim.timing import BASE_STEP
from cogblocks.sync.blending import BlenderParams, alteration, lam_step
from cogblocks.sync.coupling import Coupling

__all__ = ["BlenderParams", "DT", "SyncModel", "order_parameter", "wrap"]

TWO_PI = 2.0 * np.pi
DT = BASE_STEP


def wrap(x: np.ndarray) -> np.ndarray:
    """Wrap angles to [0, 2π)."""
    return np.mod(x, TWO_PI)


def order_parameter(theta: np.ndarray) -> np.ndarray:
    """Kuramoto order parameter ``|mean_i exp(i theta_i)|`` over the last axis."""
    # sum / n rather than mean(): the same value without mean()'s per-call overhead, which dominates here.
    n = theta.shape[-1]
    return np.hypot(np.cos(theta).sum(axis=-1) / n, np.sin(theta).sum(axis=-1) / n)


@dataclass(frozen=True, eq=False)
class SyncModel:
    """Kuramoto group with its L2 blender and L3 virtual oscillator; arrays broadcast over leading axes.

    Attributes
    ----------
    omega : ndarray, shape (..., N)
        Natural frequencies (rad/s).
    gain : float or ndarray, shape (...)
        Coupling gain.
    adjacency : ndarray or scipy.sparse matrix, shape (N, N)
        ``a_ij`` of the graph (weighted, possibly directed), zero diagonal. A sparse matrix makes
        every step cost O(edges) instead of O(N²).
    assisted : int
        0-based index of the assisted participant.
    dt : float
        Euler step (s).
    blender : BlenderParams or None
        Blender parameters (:class:`~cogblocks.sync.blending.BlenderParams`); ``None`` runs the group without L2.
    """

    omega: np.ndarray
    gain: np.ndarray | float
    adjacency: Any
    assisted: int
    dt: float = DT
    blender: BlenderParams | None = field(default_factory=BlenderParams)

    def __post_init__(self) -> None:
        n = self.adjacency.shape[0]
        if self.adjacency.shape != (n, n) or np.any(self.adjacency.diagonal() != 0):
            raise ValueError("adjacency must be square with a zero diagonal")
        if np.shape(self.omega)[-1] != n or not 0 <= self.assisted < n:
            raise ValueError(f"omega's last axis and the assisted index must match the {n} nodes")

    @classmethod
    def from_group(
        cls, group: SyncGroup, *, l2: bool = True, blender: BlenderParams | None = None, dt: float = DT
    ) -> SyncModel:
        """Model of a group on its graph (sparse for large sparse graphs); ``blender`` defaults to the deliverable's."""
        return cls(
            omega=np.asarray(group.omega, dtype=float),
            gain=group.gain,
            adjacency=Coupling(group.graph, group.n).matrix,
            assisted=group.assisted,
            dt=dt,
            blender=(blender or BlenderParams()) if l2 else None,
        )

    @property
    def n(self) -> int:
        """Number of participants."""
        return self.adjacency.shape[0]

    @cached_property
    def neighbours(self) -> np.ndarray:
        """Row ``assisted`` of the adjacency, dense: how the virtual oscillator sees the others."""
        row = self.adjacency[self.assisted]
        return np.asarray(row.toarray()).ravel() if sp.issparse(row) else row

    def _times_adjacency_t(self, x: np.ndarray) -> np.ndarray:
        """``x @ A.T`` over the last axis, through the CSR product when ``A`` is sparse."""
        if not sp.issparse(self.adjacency):
            return x @ self.adjacency.T
        flat = x.reshape(-1, self.n)
        return np.asarray(self.adjacency @ flat.T).T.reshape(x.shape)

    @property
    def others(self) -> np.ndarray:
        """Indices of the participants other than the assisted one."""
        return np.flatnonzero(np.arange(self.n) != self.assisted)

    def blend(
        self, theta: np.ndarray, theta_l3: np.ndarray, lam: np.ndarray, previous: np.ndarray | float | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Step 2 of a tick, the blender: the phases the group sees, the alteration and the next threshold.

        ``previous`` is the last tick's alteration, which the continuous blender's law remembers
        (:func:`~cogblocks.sync.blending.alteration`; ``None``: not known, no slew limit this tick); the
        deliverable's ignores it.

        Returns
        -------
        theta_tilde : ndarray, shape (..., N)
            ``theta`` with the assisted participant's phase replaced by ``theta_L2``.
        alteration : ndarray, shape (...)
            ``wrap_pi(theta_L2 - theta_L0)``.
        lam_next : ndarray, shape (...)
            Threshold of the next tick.
        """
        if self.blender is None:
            return theta, np.zeros_like(lam), lam
        theta_l0 = theta[..., self.assisted]
        shift = alteration(wrap_pi(theta_l3 - theta_l0), lam, self.blender, previous, self.dt)
        theta_l2 = wrap(theta_l0 + shift)
        altered = wrap_pi(theta_l2 - theta_l0)
        lam_next = lam_step(lam, altered, self.blender, self.dt)
        theta_tilde = theta.copy()
        theta_tilde[..., self.assisted] = theta_l2
        return theta_tilde, altered, lam_next

    def advance(
        self, theta: np.ndarray, theta_tilde: np.ndarray, theta_l3: np.ndarray, omega_l3: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Step 4 of a tick: one Euler step of the group (on ``theta_tilde``) and of the virtual oscillator."""
        gain = np.asarray(self.gain)
        # sum_j a_ij sin(t_j - t_i) = cos(t_i) (A sin t)_i - sin(t_i) (A cos t)_i: two small matrix products
        # instead of an N x N table of sines, about twice as fast at these sizes.
        sin_tilde, cos_tilde = np.sin(theta_tilde), np.cos(theta_tilde)
        pull = cos_tilde * self._times_adjacency_t(sin_tilde) - sin_tilde * self._times_adjacency_t(cos_tilde)
        theta_next = wrap(theta + self.dt * (self.omega + gain[..., None] * pull))
        # The virtual oscillator couples to its neighbours' true phases; theta_tilde differs from theta only
        # at the assisted node, which is not its own neighbour (a_aa = 0), so its sines and cosines serve.
        neighbours = self.neighbours
        pull_l3 = np.cos(theta_l3) * (sin_tilde @ neighbours) - np.sin(theta_l3) * (cos_tilde @ neighbours)
        theta_l3_next = wrap(theta_l3 + self.dt * (omega_l3 + gain * pull_l3))
        return theta_next, theta_l3_next
