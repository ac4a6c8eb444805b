"""Online identification of a Kuramoto group from its observed phases: natural frequencies and coupling gain.

For a known graph ``a_ij`` the group's Euler step is linear in the unknowns:

    wrap_π(θ_i[k+1] − θ_i[k]) / dt = ω_i + K s_i[k],   s_i[k] = Σ_j a_ij sin(θ̃_j[k] − θ̃_i[k])

(θ̃ is what the group couples to: the phases with θ_L2 in place of the assisted participant's). One tick
gives N equations in the N + 1 unknowns ``(ω_1 … ω_N, K)``; :class:`KuramotoRLS` accumulates them in
information form (``M ← ρ M + HᵀH``, ``b ← ρ b + Hᵀy``) and solves the (N + 1)-dimensional system,
which is recursive least squares with forgetting factor ρ. At the deliverable's start (all phases equal)
``s = 0``, so the frequencies are exact after one tick and K becomes identifiable as the phases spread.

Among people the frequencies drift while the coupling gain stays: ``omega_forgetting`` ρ_ω lets each ω
random-walk between ticks (the prediction step of a Kalman filter, ``M ← (M⁻¹ + Q)⁻¹`` with Q on ω only),
so ω is tracked over a memory of about ``dt / (1 − ρ_ω)`` seconds while what the ticks say about K is kept.
(Scaling the ω rows and columns of M instead would invent information on K along directions the data never
fixed.) Phase noise of σ rad/√s makes each tick's rate σ / √dt wrong, so ω's error over a memory T is about
σ / √T: the memory trades that against the drift.
:func:`~cogblocks.analysis.sync_identification.identification_errors` measures both against the true values.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from cogblocks.blocks.angles import wrap_pi
from cogblocks.blocks.specs import PHASE
from cogblocks.sim import Block, Signal
from cogblocks.sim.params import finite_array, finite_number
from cogblocks.sync.group import ring_adjacency

__all__ = ["GroupIdentifier", "KuramotoRLS", "coupling_regressor", "usable_phases"]


def coupling_regressor(theta_seen: np.ndarray, adjacency: np.ndarray) -> np.ndarray:
    """``s_i = Σ_j a_ij sin(θ̃_j − θ̃_i)``, the coefficient of K in participant i's rate."""
    return (adjacency * np.sin(theta_seen[None, :] - theta_seen[:, None])).sum(axis=1)


def usable_phases(theta: np.ndarray) -> bool:
    """Finite and within one turn of [0, 2π): a wrapped phase, not a glitch such as 1e300."""
    theta = np.asarray(theta)
    return bool(np.all(np.abs(theta - math.pi) <= 3.0 * math.pi))


class KuramotoRLS:
    """Recursive least squares on the phase increments of a Kuramoto group (the estimator of :class:`GroupIdentifier`).

    Parameters
    ----------
    adjacency : ndarray, shape (N, N)
        The known graph.
    forgetting : float
        ρ in (0, 1]; 1 weighs every tick alike, below 1 tracks slowly varying parameters
        (memory of about 1 / (1 − ρ) ticks).
    prior_omega, prior_gain : float
        Values the estimate starts from and is pulled toward with weight ``prior_weight``.
    prior_weight : float
        Regularisation of the prior, in equations' worth (keeps the system solvable before K is excited).
    max_rate : float
        A rate |Δθ/dt| above this (rad/s) is an outlier (a spike, a wrap the tracker missed): the tick is skipped.
    omega_forgetting : float, optional
        ρ_ω in (0, 1): the frequencies' own forgetting, for drifting frequencies (a random walk of ω between
        ticks; the module docstring); None: no walk.
    """

    def __init__(
        self,
        adjacency: np.ndarray,
        *,
        forgetting: float = 1.0,
        prior_omega: float = 0.0,
        prior_gain: float = 0.0,
        prior_weight: float = 1e-3,
        max_rate: float = 50.0,
        omega_forgetting: float | None = None,
    ) -> None:
        self.adjacency = np.asarray(adjacency, dtype=float)
        self.n = self.adjacency.shape[0]
        self.forgetting = forgetting
        if omega_forgetting is not None and not 0.0 < omega_forgetting < 1.0:
            allowed = "in (0, 1) or None"
            raise ValueError(f"KuramotoRLS: omega_forgetting must be {allowed}, got {omega_forgetting!r}")
        self.omega_forgetting = omega_forgetting
        self.max_rate = max_rate
        self.prior = np.r_[np.full(self.n, prior_omega), prior_gain]
        self.prior_weight = prior_weight
        self.info = np.zeros((self.n + 1, self.n + 1))
        self.rhs = np.zeros(self.n + 1)
        self.reset()

    def reset(self) -> None:
        """Forget every observation: back to the prior."""
        self.info[...] = self.prior_weight * np.eye(self.n + 1)
        self.rhs[...] = self.prior_weight * self.prior
        self.count = 0

    def observe(self, theta_seen: np.ndarray, theta_now: np.ndarray, theta_next: np.ndarray, dt: float) -> bool:
        """Add one tick's equations; ``False`` (nothing added) when a value is non-finite or a rate implausible."""
        if not (usable_phases(theta_seen) and usable_phases(theta_now) and usable_phases(theta_next)):
            return False
        rate = wrap_pi(theta_next - theta_now) / dt
        if np.any(np.abs(rate) > self.max_rate):
            return False
        s = coupling_regressor(theta_seen, self.adjacency)
        # H = [I | s]: HᵀH = [[I, s], [sᵀ, sᵀs]], Hᵀy = [y, sᵀy]
        rho = self.forgetting
        self.info *= rho
        self.rhs *= rho
        if self.omega_forgetting is not None:
            self._walk_omega()
        self.info[np.arange(self.n), np.arange(self.n)] += 1.0
        self.info[: self.n, self.n] += s
        self.info[self.n, : self.n] += s
        self.info[self.n, self.n] += s @ s
        self.rhs[: self.n] += rate
        self.rhs[self.n] += s @ rate
        self.count += 1
        return True

    def _walk_omega(self) -> None:
        """Kalman's prediction for frequencies that random-walk between ticks, in information form: the covariance
        of ω grows by ``(1 − ρ_ω)²`` (per unit of a tick's measurement variance, so that one equation a tick holds
        about ``1 / (1 − ρ_ω)`` ticks' worth on each ω), K's does not; the estimate stays where it is."""
        x = np.linalg.solve(self.info, self.rhs)
        covariance = np.linalg.inv(self.info)
        walk = np.arange(self.n)
        covariance[walk, walk] += (1.0 - self.omega_forgetting) ** 2
        self.info[...] = np.linalg.inv(covariance)
        self.info += self.info.T
        self.info *= 0.5  # symmetric to the rounding, as the information must be
        self.rhs[...] = self.info @ x

    def estimate(self) -> tuple[np.ndarray, float]:
        """The current ``(ω, K)``."""
        x = np.linalg.solve(self.info, self.rhs)
        return x[: self.n], float(x[self.n])

    def gain_excitation(self) -> float:
        """Information on K left once the frequencies are accounted for (the Schur complement; 0: K unknown)."""
        diag = np.diag(self.info)[: self.n]
        col = self.info[: self.n, self.n]
        return float(self.info[self.n, self.n] - col @ (col / diag))


class GroupIdentifier(Block):
    """Identify a Kuramoto group online: natural frequencies ω and coupling gain K from the observed phases.

    Every tick adds the equations ``wrap_π(θ_i[k] − θ_i[k−1]) / dt = ω_i + K s_i[k−1]`` to a recursive
    least-squares estimate (:class:`KuramotoRLS`; ``s_i`` is the coupling sum on the phases the group
    saw, with ``theta_l2`` in place of the assisted participant's when ``assisted`` is set).

    Ports
    -----
    theta : input, shape (N,), rad, wrapped
        The participants' own phases.
    theta_l2 : input, scalar, rad, wrapped (only with ``assisted``)
        The phase the group saw for the assisted participant.
    omega : output, shape (N,), rad/s
        Estimated natural frequencies (the prior until the first usable tick).
    gain : output, scalar
        Estimated coupling gain.

    Parameters
    ----------
    n : int
        Number of participants.
    adjacency : "ring" or array_like
        The known graph, ``a_ij``.
    assisted : int, optional
        0-based index of the assisted participant, which adds the ``theta_l2`` input.
    forgetting : float
        Forgetting factor ρ in (0, 1] of the least squares.
    prior_omega, prior_gain : float
        Start of the estimates.
    max_rate : float
        Rates above this (rad/s) are outliers.

    Notes
    -----
    Bad data policy: a tick whose phases (or θ_L2) are not all finite and within one turn of [0, 2π),
    or that implies a rate above ``max_rate``, adds no equation, nor does the tick after it (an
    increment needs two good samples); the outputs hold their last estimate.
    """

    def __init__(
        self,
        n: int,
        *,
        adjacency: Any = "ring",
        assisted: int | None = None,
        forgetting: float = 1.0,
        prior_omega: float = 0.0,
        prior_gain: float = 0.0,
        max_rate: float = 50.0,
        period: float | None = None,
    ) -> None:
        super().__init__(period=period)
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 2:
            raise ValueError(f"GroupIdentifier: n must be an integer >= 2, got {n!r}")
        if isinstance(adjacency, str):
            if adjacency != "ring":
                raise ValueError(f"GroupIdentifier: adjacency must be 'ring' or an {n}x{n} matrix, got {adjacency!r}")
            adjacency = ring_adjacency(n)
        adjacency = finite_array(self, "adjacency", adjacency, shape=(n, n))
        if assisted is not None and (
            isinstance(assisted, bool) or not isinstance(assisted, (int, np.integer)) or not 0 <= assisted < n
        ):
            raise ValueError(
                f"GroupIdentifier: assisted must be a 0-based index in [0, {n - 1}] or None, got {assisted!r}"
            )
        self.n, self.assisted = int(n), None if assisted is None else int(assisted)
        forgetting = finite_number(self, "forgetting", forgetting, low=0.0, high=1.0, low_open=True)
        prior_omega = finite_number(self, "prior_omega", prior_omega)
        prior_gain = finite_number(self, "prior_gain", prior_gain)
        max_rate = finite_number(self, "max_rate", max_rate, low=0.0, low_open=True)
        self.rls = KuramotoRLS(
            adjacency, forgetting=forgetting, prior_omega=prior_omega, prior_gain=prior_gain, max_rate=max_rate
        )
        self.add_input("theta", PHASE.with_(shape=(n,)), feedthrough=False)
        if self.assisted is not None:
            self.add_input("theta_l2", PHASE, feedthrough=False)
        self.add_output("omega", Signal(shape=(n,), unit="rad/s"), initial=np.full(n, prior_omega))
        self.add_output("gain", Signal(unit="1/s"), initial=prior_gain)
        self.add_state("info", self.rls.info)
        self.add_state("rhs", self.rls.rhs)
        self.add_state("previous", np.full(n, math.nan))  # θ̃ of the tick before (NaN: none usable)
        self.add_state("previous_own", np.full(n, math.nan))
        self.add_state("estimate", np.r_[np.full(n, prior_omega), prior_gain])

    def output(self, k: int) -> None:
        self.omega.value[...] = self.estimate[: self.n]
        self.gain.value[...] = self.estimate[self.n]

    def update(self, k: int) -> None:
        # the RLS arrays are this block's declared state (shared in place), so reset and snapshots cover them
        self.rls.info, self.rls.rhs = self.info, self.rhs
        theta = np.asarray(self.theta.value, dtype=float)
        seen = theta.copy()
        if self.assisted is not None:
            seen[self.assisted] = float(self.theta_l2.value)
        dt = self.dt * self.every
        if usable_phases(self.previous) and self.rls.observe(self.previous, self.previous_own, theta, dt):
            omega, gain = self.rls.estimate()
            if np.isfinite(omega).all() and math.isfinite(gain):
                self.estimate[...] = np.r_[omega, gain]
        good = usable_phases(seen) and usable_phases(theta)
        self.previous[...] = seen if good else math.nan
        self.previous_own[...] = theta if good else math.nan
