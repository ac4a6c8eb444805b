"""Kuramoto models of a group's oscillatory motion and its order parameter (section 5.2.1)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from cogblocks.blocks.angles import TWO_PI, wrap_angle
from cogblocks.sim import Block, Signal
from cogblocks.sim.params import finite_array, finite_number, positive_int, random_generator

__all__ = ["ArmPositions", "KuramotoGroup", "KuramotoOscillator", "OrderParameter", "ring_adjacency"]

PHASE = Signal(unit="rad", wrapped=True)
_BELOW_TWO_PI = np.nextafter(TWO_PI, 0.0)


def ring_adjacency(n: int) -> np.ndarray:
    """Adjacency matrix of a ring of ``n`` participants (each sees its two neighbours)."""
    n = positive_int("ring_adjacency", "n", n, minimum=2)
    a = np.zeros((n, n))
    for i in range(n):
        a[i, (i + 1) % n] = a[i, (i - 1) % n] = 1.0
    return a


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
        Natural frequencies in rad/s, one per participant.
    gain : float
        Coupling gain, >= 0.
    adjacency : "ring" or array_like
        Who sees whom: ``a_ij = 1`` when i is coupled to j. A ring by default.
    assisted : int, optional
        0-based index of the assisted participant, which adds the ``theta_l2`` input.
    theta0 : array_like
        Initial phases (0 by default, as in the deliverable).

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
        period: float | None = None,
    ) -> None:
        super().__init__(period=period)
        self.omega0 = finite_array(self, "omega", omega, ndim=1)
        n = len(self.omega0)
        if n < 2:
            raise ValueError(f"KuramotoGroup: omega must hold at least 2 frequencies, got {n}")
        self.n = n
        self.gain = finite_number(self, "gain", gain, low=0.0)
        if isinstance(adjacency, str):
            if adjacency != "ring":
                raise ValueError(f"KuramotoGroup: adjacency must be 'ring' or an {n}x{n} matrix, got {adjacency!r}")
            adjacency = ring_adjacency(n)
        self.adjacency = finite_array(self, "adjacency", adjacency, shape=(n, n))
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
        self._seen = np.zeros(n)
        self._diff = np.zeros((n, n))
        self._rate = np.zeros(n)

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
        d = self._diff
        np.subtract(seen[None, :], seen[:, None], out=d)
        np.sin(d, out=d)
        d *= self.adjacency
        rate = np.add.reduce(d, axis=1, out=self._rate)
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


class OrderParameter(Block):
    """Kuramoto order parameter ``r = |mean_i exp(j θ_i)|`` (eq. 2), in [0, 1].

    Ports: input ``theta`` (shape (N,), rad), output ``r`` (scalar, dimensionless).

    Notes
    -----
    Bad data policy: non-finite phases are left out of the mean; with no finite
    phase the output holds its last value.
    """

    def __init__(self, *, period: float | None = None) -> None:
        super().__init__(period=period)
        self.add_input("theta", Signal(shape=None, unit="rad", wrapped=None))
        self.add_output("r", Signal(), initial=1.0)

    def setup(self) -> None:
        if len(self.theta.spec.shape) != 1 or self.theta.spec.shape[0] < 1:
            raise self._fail(f"theta must be a vector of phases, got shape {self.theta.spec.shape}")
        self._n = self.theta.spec.shape[0]

    def output(self, k: int) -> None:
        theta = self.theta.value
        if not math.isfinite(np.add.reduce(theta)):  # one cheap check keeps cos/sin off inf and NaN
            theta = theta[np.isfinite(theta)]
            if theta.size == 0:
                return
        self.r.value[...] = math.hypot(np.add.reduce(np.cos(theta)), np.add.reduce(np.sin(theta))) / theta.size


class ArmPositions(Block):
    """Phases to 1D arm positions: ``p_i = offset_i + amplitude_i cos θ_i + noise``.

    The PoP's participants move an arm back and forth along one axis; this
    block turns the group's phases into such position signals, so that the
    architecture can be run on positions, as on a real sensor stream.

    Ports: input ``theta`` (shape (N,), rad), output ``p`` (shape (N,), mm).

    Parameters
    ----------
    amplitude : float or array_like
        Half the range of motion per participant, mm (> 0).
    offset : float or array_like
        Centre of the motion per participant, mm.
    noise_std : float
        Standard deviation of white measurement noise, mm (>= 0).
    seed : int or numpy.random.Generator, optional
        Seed of the noise (part of the block's state, so snapshots replay it).

    Notes
    -----
    Bad data policy: stateless and element-wise, so a non-finite input element
    gives a non-finite output element on the same tick (as in NumPy) and
    nothing else; blocks with memory downstream decide how to treat it.
    """

    def __init__(
        self,
        n: int,
        amplitude: Any = 150.0,
        offset: Any = 0.0,
        *,
        noise_std: float = 0.0,
        seed: int | np.random.Generator | None = None,
        period: float | None = None,
    ) -> None:
        super().__init__(period=period)
        self.n = positive_int(self, "n", n)
        self.amplitude = np.broadcast_to(finite_array(self, "amplitude", amplitude), (n,)).copy()
        if np.any(self.amplitude <= 0):
            raise ValueError(f"ArmPositions: amplitude must be > 0 for every participant, got {amplitude!r}")
        self.offset = np.broadcast_to(finite_array(self, "offset", offset), (n,)).copy()
        self.noise_std = finite_number(self, "noise_std", noise_std, low=0.0)
        self.add_input("theta", Signal(shape=(n,), unit="rad", wrapped=None))
        self.add_output("p", shape=(n,), unit="mm")
        rng = random_generator(self, "seed", seed)
        # the noise of a tick is drawn in the previous tick's update, so output() leaves the state alone
        self.add_state("noise", self._draw(rng))
        self.add_state("rng", rng)

    def _draw(self, rng: np.random.Generator) -> np.ndarray:
        return rng.normal(scale=self.noise_std, size=self.n) if self.noise_std > 0 else np.zeros(self.n)

    @np.errstate(invalid="ignore")  # a non-finite phase gives a NaN position (documented), silently
    def output(self, k: int) -> None:
        p = self.p.value
        np.cos(self.theta.value, out=p)
        p *= self.amplitude
        p += self.offset
        p += self.noise

    def update(self, k: int) -> None:
        self.noise = self._draw(self.rng)
