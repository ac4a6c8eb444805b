"""The group plant of the PoP of Social Connectedness: Kuramoto oscillators on a graph (model 1, Table 2)."""

from __future__ import annotations

import copy
import math
from typing import TYPE_CHECKING, Any

import numpy as np

from cogblocks.blocks.angles import TWO_PI, wrap_angle
from cogblocks.blocks.specs import PHASE
from cogblocks.data.graphs import ring_adjacency
from cogblocks.sim import Block
from cogblocks.sim.params import finite_array, finite_number, positive_int, random_generator
from cogblocks.sim.timing import BASE_STEP
from cogblocks.sync.coupling import Coupling, checked_graph

if TYPE_CHECKING:
    from cogblocks.data.groups import SyncGroup

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
    noise : float or array_like
        Phase noise σ_i in rad/√s (a number for everyone or one per
        participant), >= 0: Euler–Maruyama adds ``σ_i √dt ξ_i`` to each step.
    drift_spread : float or array_like
        Frequency drift as a fraction of ``|ω_i|``, >= 0: each frequency is
        ``ω_i + δ_i(t)`` with δ_i an Ornstein–Uhlenbeck process of stationary
        standard deviation ``drift_spread_i · |ω_i|`` (rad/s), starting at 0
        (the group's frequencies are the ones at t = 0).
    drift_tau : float
        Time constant of the drift in s, > 0 (δ's autocorrelation is
        ``exp(−lag / drift_tau)``; stepped exactly, not by Euler).
    seed : int, SeedSequence, Generator or sequence of int
        Seed of the noise. Each tick draws one fixed vector of 2N standard
        normals (phase noise, then drift), whatever the phases and inputs, so
        two blocks with the same seed see the same noise whatever L2 does
        (common random numbers). A sequence gives one seed per run of a batch.

    Notes
    -----
    The block runs a batch of runs at once (``compile(dt, batch=B)``): ``omega`` and ``theta0``
    may then hold one row per run (shape (B, N)), ``gain`` one value per run (shape (B,)), ``seed``
    one seed per run; each row is the run of a block built with that row's values, bit for bit.

    Bad data policy: for that tick, a non-finite frequency is replaced by the
    constructor's ``omega`` and a non-finite θ_L2 by the assisted
    participant's own phase, so the phases stay finite.

    With ``noise`` and ``drift_spread`` both 0 (the default) the block draws
    nothing and holds no noise state: the plant is the noise-free one, bit for
    bit. Otherwise its state also holds the generator (``rng``) and the drift
    (``drift``, rad/s), so a snapshot restores the noise where it was.
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
        noise: Any = 0.0,
        drift_spread: Any = 0.0,
        drift_tau: float = 10.0,
        seed: Any = 0,
    ) -> None:
        super().__init__(period=period)
        self.omega0 = finite_array(self, "omega", omega)
        if self.omega0.ndim not in (1, 2):
            raise ValueError(
                f"KuramotoGroup: omega must have shape (N,), or (B, N) for a batch of B runs, got {self.omega0.shape}"
            )
        if np.any(np.abs(self.omega0) > MAX_OMEGA):
            raise ValueError(
                f"KuramotoGroup: omega must lie in [-{MAX_OMEGA:g}, {MAX_OMEGA:g}] rad/s (about "
                f"{MAX_OMEGA / TWO_PI:.0f} Hz, above any human movement), got {np.max(np.abs(self.omega0)):.3g}"
            )
        n = self.omega0.shape[-1]
        if n < 2:
            raise ValueError(f"KuramotoGroup: omega must hold at least 2 frequencies, got {n}")
        self.n = n
        if np.ndim(gain) == 1:  # one gain per run of a batch
            self.gain = finite_array(self, "gain", gain, ndim=1)
            if np.any(self.gain < 0):
                raise ValueError(f"KuramotoGroup: gain must be >= 0, got {gain!r}")
        else:
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
        if theta0.shape not in ((), (n,)) and not (theta0.ndim == 2 and theta0.shape[1] == n):
            raise ValueError(
                f"KuramotoGroup: theta0 must be a number or of shape ({n},), or (B, {n}) for a batch, "
                f"got shape {theta0.shape}"
            )
        self._theta0 = np.mod(np.broadcast_to(theta0, theta0.shape[:-1] + (n,) if theta0.ndim else (n,)), TWO_PI)
        self.add_input("omega", shape=(n,), unit="rad/s", default=self.omega0, feedthrough=False)
        if self.assisted is not None:
            self.add_input("theta_l2", PHASE, feedthrough=False)
        self.add_output("theta", PHASE.with_(shape=(n,)), initial=self._theta0)
        self.add_state("phase", self._theta0.astype(float))
        self.add_scratch("_seen", np.zeros(n))  # the phases and pulls of this tick, work buffers
        self.add_scratch("_rate", np.zeros(n))
        self._init_noise(noise, drift_spread, drift_tau, seed)

    def _per_participant(self, name: str, value: Any) -> np.ndarray:
        array = finite_array(self, name, value)
        if array.shape not in ((), (self.n,)) or np.any(array < 0):
            raise ValueError(f"KuramotoGroup: {name} must be a number >= 0 or {self.n} numbers >= 0, got {value!r}")
        return np.broadcast_to(array, (self.n,)).astype(float)

    def _init_noise(self, noise: Any, drift_spread: Any, drift_tau: float, seed: Any) -> None:
        self.noise = self._per_participant("noise", noise)
        self.drift_spread = self._per_participant("drift_spread", drift_spread)
        self.drift_tau = finite_number(self, "drift_tau", drift_tau, low=0.0)
        if not self.drift_tau > 0:
            raise ValueError(f"KuramotoGroup: drift_tau must be > 0 s, got {drift_tau!r}")
        self.noisy = bool(self.noise.any() or self.drift_spread.any())
        # checked even without noise: a bad seed is a mistake either way
        many = isinstance(seed, (list, tuple, np.ndarray))
        if many and len(seed) == 0:
            raise ValueError("KuramotoGroup: seed must be a seed or a non-empty sequence of per-run seeds, got []")
        # the generators as built, never drawn from: each compile starts the runs' generators from copies
        self._pristine = [random_generator(self, "seed", s) for s in (seed if many else [seed])]
        self._per_run_seeds = many
        if self.noisy:
            self.add_state("rng", copy.deepcopy(self._pristine[0]))
            self.add_state("drift", np.zeros(self.n))
            self.add_scratch("_draw", np.zeros(2 * self.n))  # the tick's normal draws, a work buffer

    batchable = True

    def setup(self) -> None:
        super().setup()
        self._size_for_batch()
        if self.noisy:  # the step's constants, once dt is known
            decay = math.exp(-self.dt / self.drift_tau)
            self._decay = decay
            self._kick = self.drift_spread * np.abs(self.omega0) * math.sqrt(1.0 - decay * decay)
            self._diffusion = self.noise * math.sqrt(self.dt)

    def _size_for_batch(self) -> None:
        """The state and work buffers with the batch axis; rows of per-run parameters checked against the batch."""
        lead, n = self.batch_shape, self.n
        gain = np.asarray(self.gain)
        for name, value in (
            ("omega", self.omega0),
            ("theta0", self._theta0),
            ("gain", gain[:, None] if gain.ndim else gain),
        ):
            if value.ndim == 2 and value.shape[0] != self.batch:
                raise self._fail(
                    f"{name} holds {value.shape[0]} runs (shape {value.shape}); compile with batch={value.shape[0]}"
                )
        seeds = self._pristine
        if self._per_run_seeds and len(seeds) != self.batch:
            raise self._fail(f"seed holds {len(seeds)} per-run seeds; compile with batch={len(seeds)}")
        self.add_state("phase", np.array(np.broadcast_to(self._theta0, lead + (n,)), dtype=float))
        self.add_scratch("_seen", np.zeros(lead + (n,)))
        self.add_scratch("_rate", np.zeros(lead + (n,)))
        self.coupling.size_for(lead)
        self._gain = gain[:, None] if gain.ndim else self.gain  # broadcasts over each run's participants
        if self.noisy:
            self.add_state("drift", np.zeros(lead + (n,)))
            self.add_scratch("_draw", np.zeros(lead + (2 * n,)))
            if self.batch is None:
                self.add_state("rng", copy.deepcopy(seeds[0]))
            else:  # one generator per run: each row draws what its own run would
                self.add_state("rng", [copy.deepcopy(seeds[b if len(seeds) > 1 else 0]) for b in range(self.batch)])

    @classmethod
    def for_group(cls, group: SyncGroup, *, assisted: bool = True, adjacency: Any = None) -> KuramotoGroup:
        """The plant of a :class:`~cogblocks.data.groups.SyncGroup`: its frequencies, gain, graph (or
        ``adjacency``) and noise (``group.plant_options()``), its assisted participant unless ``assisted=False``."""
        graph = group.graph if adjacency is None else adjacency
        index = group.assisted if assisted else None
        return cls(group.omega, group.gain, adjacency=graph, assisted=index, **group.plant_options())

    def output(self, k: int) -> None:
        self.theta.value[...] = self.phase

    def update(self, k: int) -> None:
        seen = self._seen
        seen[...] = self.phase
        if self.assisted is not None and self.batch is not None:  # each run's own θ_L2, where finite
            theta_l2 = self.theta_l2.value
            np.copyto(seen[:, self.assisted], theta_l2, where=np.isfinite(theta_l2))
        elif self.assisted is not None:
            theta_l2 = float(self.theta_l2.value)
            if math.isfinite(theta_l2):
                seen[self.assisted] = theta_l2
        omega = self.omega.value
        if self.omega.driven and not np.isfinite(omega).all():  # the default is finite by construction
            omega = np.where(np.isfinite(omega), omega, self.omega0)
        rate = self.coupling.pull(seen, self._rate)
        rate *= self._gain
        rate += omega
        rate *= self.dt
        phase = self.phase
        phase += rate
        if self.noisy:
            self._add_noise(phase)
        np.mod(phase, TWO_PI, out=phase)
        np.minimum(phase, _BELOW_TWO_PI, out=phase)  # np.mod gives 2π for tiny negative values

    def noise_path(self, n_steps: int, dt: float = BASE_STEP) -> np.ndarray:
        """The noise's phase increments of the first ``n_steps`` ticks from the block's initial noise state.

        Row k is what tick k adds to the phases beyond the noise-free step (``dt δ_k + σ √dt ξ_k``, rad),
        whatever the phases: the noise is an exogenous input, known to a clairvoyant controller
        (:func:`~cogblocks.analysis.sync_ocp.windowed_control_bound` on a noisy group). Zeros without noise.
        """
        return self._paths(n_steps, dt)[0]

    def drift_path(self, n_steps: int, dt: float = BASE_STEP) -> np.ndarray:
        """The frequency drift δ_k (rad/s) in force at each of the first ``n_steps`` ticks: the true ω_i(t) − ω_i."""
        return self._paths(n_steps, dt)[1]

    def _paths(self, n_steps: int, dt: float) -> tuple[np.ndarray, np.ndarray]:
        n_steps = positive_int(self, "n_steps", n_steps, minimum=0)
        path, drifts = np.zeros((n_steps, self.n)), np.zeros((n_steps, self.n))
        if not self.noisy:
            return path, drifts
        if self._per_run_seeds:
            raise ValueError("KuramotoGroup: noise_path and drift_path are those of a block with one seed")
        rng = copy.deepcopy(self._pristine[0])
        decay = math.exp(-dt / self.drift_tau)
        kick = self.drift_spread * np.abs(self.omega0) * math.sqrt(1.0 - decay * decay)
        diffusion = self.noise * math.sqrt(dt)
        drift = np.array(self._state_init["drift"], dtype=float)
        draw = np.zeros(2 * self.n)
        for k in range(n_steps):  # the order of _add_noise's operations
            rng.standard_normal(out=draw)
            drifts[k] = drift
            path[k] = dt * drift
            path[k] += diffusion * draw[: self.n]
            drift *= decay
            drift += kick * draw[self.n :]
        return path, drifts

    def _add_noise(self, phase: np.ndarray) -> None:
        """This tick's drift and diffusion; one draw of 2N normals per tick whatever the state (common numbers)."""
        n, draw, drift = self.n, self._draw, self.drift
        if self.batch is None:
            self.rng.standard_normal(out=draw)
        else:
            for generator, row in zip(self.rng, draw, strict=True):
                generator.standard_normal(out=row)
        phase += self.dt * drift
        phase += self._diffusion * draw[..., :n]
        drift *= self._decay
        drift += self._kick * draw[..., n:]


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
