"""The group plant of the PoP of Social Connectedness: Kuramoto oscillators on a graph (model 1, Table 2)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from cogblocks.blocks.angles import TWO_PI, wrap_angle
from cogblocks.blocks.specs import PHASE
from cogblocks.data.graphs import ring_adjacency
from cogblocks.sim import Block
from cogblocks.sim.params import finite_array, finite_number, positive_int
from cogblocks.sync.coupling import Coupling, checked_graph

__all__ = ["MAX_OMEGA", "KuramotoGroup", "KuramotoOscillator", "ring_adjacency"]

_BELOW_TWO_PI = np.nextafter(TWO_PI, 0.0)

#: Largest natural frequency a group accepts, rad/s (about 16 Hz). Voluntary rhythmic limb movement stays
#: below about 7 Hz (fast finger tapping) and physiological tremor below about 12 Hz, so nothing a person
#: does is refused; and at the 10 ms base step a phase then moves at most 1 rad per tick, well inside the
#: 100 Hz sampling's Nyquist limit (pi rad per tick) that a phase estimate needs.
MAX_OMEGA = 100.0


class KuramotoGroup(Block):
    """A group of Kuramoto oscillators integrated by forward Euler (model 1 of the deliverable).

    ``θ_i ← wrap(θ_i + dt (ω_i + gain Σ_j a_ij sin(θ̃_j − θ̃_i)))`` with phases
    wrapped to ``[0, 2π)`` after every step. ``gain`` multiplies the sum as is
    (it is *not* divided by N again; Table 2's ``c`` is the gain). When
    ``assisted`` is set, the phase displayed for that participant (the L2
    avatar's, input ``theta_l2``) replaces its own in everyone's coupling,
    its own included: ``θ̃_assisted = θ_L2``.

    Ports
    -----
    omega : input, shape (N,), rad/s, optional
        Natural frequencies; defaults to the constant ``omega`` parameter.
    theta_l2 : input, scalar, rad, wrapped (only with ``assisted``)
        Displayed phase of the assisted participant.
    theta : output, shape (N,), rad, wrapped
        The participants' own phases (θ_L0 for the assisted one).

    Parameters
    ----------
    omega : array_like
        Natural frequencies in rad/s, one per participant, within ±:data:`MAX_OMEGA` (100 rad/s).
    gain : float
        Coupling gain, >= 0.
    adjacency : "ring", "all", ("random", p, seed), array_like or scipy.sparse matrix
        Who sees whom: ``a_ij`` is the weight with which i sees j (weighted,
        possibly directed; see :mod:`cogblocks.data.graphs`). A ring by default.
        The coupling is computed on the edge list, in O(edges), for groups
        larger than 64 with at most a quarter of the N² entries linked
        (:func:`~cogblocks.sync.coupling.use_sparse`), else as a dense product.
    assisted : int, optional
        0-based index of the assisted participant, which adds the ``theta_l2`` input.
    theta0 : array_like
        Initial phases (0 by default, as in the deliverable).
    sparse : bool, optional
        Force the edge-list (True) or the dense (False) coupling; chosen from
        the graph's size and density by default.

    Notes
    -----
    Bad data policy: for that tick, a non-finite frequency is replaced by the
    constructor's ``omega`` and a non-finite θ_L2 by the assisted
    participant's own phase, so the phases stay finite.
    """

    def __init__(
        self,
        omega: Any,
        gain: float,
        *,
        adjacency: Any = "ring",
        assisted: int | None = None,
        theta0: Any = 0.0,
        sparse: bool | None = None,
        period: float | None = None,
    ) -> None:
        super().__init__(period=period)
        self.omega0 = finite_array(self, "omega", omega, ndim=1)
        if np.any(np.abs(self.omega0) > MAX_OMEGA):
            raise ValueError(
                f"KuramotoGroup: omega must lie in [-{MAX_OMEGA:g}, {MAX_OMEGA:g}] rad/s (about "
                f"{MAX_OMEGA / TWO_PI:.0f} Hz, above any human movement), got {np.max(np.abs(self.omega0)):.3g}"
            )
        n = len(self.omega0)
        if n < 2:
            raise ValueError(f"KuramotoGroup: omega must hold at least 2 frequencies, got {n}")
        self.n = n
        self.gain = finite_number(self, "gain", gain, low=0.0)
        if sparse is not None and not isinstance(sparse, (bool, np.bool_)):
            raise ValueError(f"KuramotoGroup: sparse must be True, False or None, got {sparse!r}")
        self.add_scratch("coupling", None)  # the graph and its work buffer
        self.coupling = Coupling(checked_graph(self, adjacency, n), n, sparse=sparse)
        self.adjacency = self.coupling.matrix
        if assisted is not None and (
            isinstance(assisted, bool) or not isinstance(assisted, (int, np.integer)) or not 0 <= assisted < n
        ):
            raise ValueError(
                f"KuramotoGroup: assisted must be a 0-based index in [0, {n - 1}] or None, got {assisted!r}"
            )
        self.assisted = None if assisted is None else int(assisted)
        theta0 = finite_array(self, "theta0", theta0)
        if theta0.shape not in ((), (n,)):
            raise ValueError(f"KuramotoGroup: theta0 must be a number or of shape ({n},), got shape {theta0.shape}")
        theta0 = np.broadcast_to(theta0, (n,))
        self.add_input("omega", shape=(n,), unit="rad/s", default=self.omega0, feedthrough=False)
        if self.assisted is not None:
            self.add_input("theta_l2", PHASE, feedthrough=False)
        self.add_output("theta", PHASE.with_(shape=(n,)), initial=np.mod(theta0, TWO_PI))
        self.add_state("phase", np.mod(theta0, TWO_PI).astype(float))
        self.add_scratch("_seen", np.zeros(n))  # the phases and pulls of this tick, work buffers
        self.add_scratch("_rate", np.zeros(n))

    def output(self, k: int) -> None:
        self.theta.value[...] = self.phase

    def update(self, k: int) -> None:
        seen = self._seen
        seen[...] = self.phase
        if self.assisted is not None:
            theta_l2 = float(self.theta_l2.value)
            if math.isfinite(theta_l2):
                seen[self.assisted] = theta_l2
        omega = self.omega.value
        if self.omega.driven and not np.isfinite(omega).all():  # the default is finite by construction
            omega = np.where(np.isfinite(omega), omega, self.omega0)
        rate = self.coupling.pull(seen, self._rate)
        rate *= self.gain
        rate += omega
        rate *= self.dt
        phase = self.phase
        phase += rate
        np.mod(phase, TWO_PI, out=phase)
        np.minimum(phase, _BELOW_TWO_PI, out=phase)  # np.mod gives 2π for tiny negative values


class KuramotoOscillator(Block):
    """One Kuramoto oscillator coupled to ``n_neighbours`` scalar phase inputs.

    ``θ ← wrap(θ + dt (ω + gain Σ_j sin(θ_j − θ)))``. Lets a group be built one
    block per participant (each with its own rate or model).

    Ports: inputs ``theta_0 … theta_{n-1}`` (rad, not feedthrough), output ``theta``.

    Notes
    -----
    Bad data policy: a non-finite neighbour phase is left out of the coupling
    for that tick.
    """

    def __init__(
        self,
        omega: float,
        gain: float,
        n_neighbours: int,
        *,
        theta0: float = 0.0,
        period: float | None = None,
    ) -> None:
        super().__init__(period=period)
        self.omega = finite_number(self, "omega", omega)
        self.gain = finite_number(self, "gain", gain, low=0.0)
        n = positive_int(self, "n_neighbours", n_neighbours, minimum=0)
        self._neighbours = [self.add_input(f"theta_{j}", PHASE, feedthrough=False) for j in range(n)]
        theta0 = finite_number(self, "theta0", theta0) % TWO_PI
        self.add_output("theta", PHASE, initial=theta0)
        self.add_state("phase", theta0)

    def output(self, k: int) -> None:
        self.theta.value[...] = self.phase

    def update(self, k: int) -> None:
        phase = self.phase
        coupling = 0.0
        for port in self._neighbours:
            other = float(port.value)
            if math.isfinite(other):
                coupling += math.sin(other - phase)
        self.phase = wrap_angle(phase + self.dt * (self.omega + self.gain * coupling))
