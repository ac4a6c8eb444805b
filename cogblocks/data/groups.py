"""Kuramoto groups of the PoP of Social Connectedness (Table 2 of the deliverable, section 5.2.3.2).

Table 2 numbers the assisted participant from 1 (#4 in Group 1, #6 in Groups 2 and 3); here
``assisted`` is the 0-based index into ``omega`` (3 and 5). ``gain`` is Table 2's column ``c``
exactly as the simulation uses it (1.6, 1.25/7 and 4.4/7): it multiplies the coupling sum and is not
divided by N again. Group numbers follow Table 2, not Table 3 (whose rows are numbered differently).

:func:`random_groups` draws held-out groups on any graph (see its docstring for the distribution).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.sparse.csgraph import connected_components

from cogblocks.data.graphs import adjacency_matrix, is_random_graph, random_graph_params

__all__ = [
    "NOISE_RANGES",
    "SPLITS",
    "GroupNoise",
    "SyncGroup",
    "TABLE2",
    "TABLE3_CHANGE_PCT",
    "locking_gain",
    "random_groups",
]


@dataclass(frozen=True)
class GroupNoise:
    """Phase noise and frequency drift of a group's participants (the options of ``KuramotoGroup``).

    Attributes
    ----------
    sigma : tuple of float
        Phase noise σ_i per participant, rad/√s (Euler–Maruyama: ``σ_i √dt ξ`` per step).
    drift_spread : tuple of float
        Stationary standard deviation of each frequency's Ornstein–Uhlenbeck drift, as a fraction of ``abs(ω_i)``.
    drift_tau : float
        Time constant of the drift, s.
    seed : int
        Seed of the noise draw: the run without L2 and every run with L2 see the same noise.
    """

    sigma: tuple[float, ...]
    drift_spread: tuple[float, ...]
    drift_tau: float
    seed: int

    def __post_init__(self) -> None:
        if len(self.sigma) != len(self.drift_spread):
            raise ValueError(f"GroupNoise: {len(self.sigma)} sigmas for {len(self.drift_spread)} drift spreads")
        if min(self.sigma + self.drift_spread, default=0.0) < 0 or not self.drift_tau > 0 or self.seed < 0:
            raise ValueError("GroupNoise: sigma and drift_spread must be >= 0, drift_tau > 0 and seed >= 0")

    def as_dict(self) -> dict[str, Any]:
        """The parameters as JSON-ready numbers and lists."""
        return {
            "sigma": list(self.sigma),
            "drift_spread": list(self.drift_spread),
            "drift_tau": self.drift_tau,
            "seed": self.seed,
        }


@dataclass(frozen=True)
class SyncGroup:
    """Parameters of one simulated group (all phases starting at 0 rad).

    Attributes
    ----------
    name : str
        Human-readable label with the data source.
    n : int
        Number of participants.
    gain : float
        Coupling gain multiplying ``sum_j a_ij sin(theta_j - theta_i)``.
    omega : tuple of float
        Natural frequencies in rad/s, one per participant.
    assisted : int
        0-based index of the participant whose motion the L2 architecture alters.
    duration : float
        Simulated time in seconds.
    graph : "ring", "all", ("random", p, seed) or matrix
        Who sees whom (see :mod:`cogblocks.data.graphs`); a ring by default. A matrix (weighted,
        possibly directed, zero diagonal; ``a_ij`` is how strongly i sees j) is stored as a tuple of
        tuples so that the group stays hashable.
    noise : GroupNoise, optional
        Phase noise and frequency drift of the participants; None (the default) is the noise-free group.
    """

    name: str
    n: int
    gain: float
    omega: tuple[float, ...]
    assisted: int
    duration: float
    graph: Any = "ring"
    noise: GroupNoise | None = None

    def __post_init__(self) -> None:
        if len(self.omega) != self.n:
            raise ValueError(f"{self.name}: {len(self.omega)} frequencies for n = {self.n}")
        if self.noise is not None and len(self.noise.sigma) != self.n:
            raise ValueError(f"{self.name}: noise for {len(self.noise.sigma)} participants, n = {self.n}")
        if not 0 <= self.assisted < self.n:
            raise ValueError(f"{self.name}: assisted index {self.assisted} outside 0..{self.n - 1}")
        graph = self.graph
        if is_random_graph(graph):
            p, seed = random_graph_params(graph)
            graph = ("random", p, seed)
        elif not isinstance(graph, str):
            matrix = adjacency_matrix(graph, self.n)
            if np.any(np.diag(matrix) != 0):
                raise ValueError(f"{self.name}: the adjacency matrix must have a zero diagonal")
            graph = tuple(tuple(float(x) for x in row) for row in matrix)
        adjacency_matrix(graph, self.n)  # rejects unknown names and bad random specs
        object.__setattr__(self, "graph", graph)

    def adjacency(self, *, sparse: bool = False) -> Any:
        """The group's adjacency matrix, dense (default) or CSR."""
        return adjacency_matrix(self.graph, self.n, sparse=sparse)

    def plant_options(self) -> dict[str, Any]:
        """The noise options of ``KuramotoGroup`` for this group (none for a noise-free group)."""
        if self.noise is None:
            return {}
        noise = self.noise
        return {
            "noise": noise.sigma,
            "drift_spread": noise.drift_spread,
            "drift_tau": noise.drift_tau,
            "seed": noise.seed,
        }

    @property
    def graph_kind(self) -> str:
        """``"ring"``, ``"all"``, ``"random"`` or ``"matrix"``."""
        return self.graph if isinstance(self.graph, str) else "random" if is_random_graph(self.graph) else "matrix"


TABLE2: dict[int, SyncGroup] = {
    1: SyncGroup(
        name="Group 1 (Calabrese et al. 2022)",
        n=5,
        gain=1.6,
        omega=(3.04, 6.36, 3.34, 9.91, 5.21),
        assisted=3,
        duration=10.0,
    ),
    2: SyncGroup(
        name="Group 2 (Alderisio et al. 2017, group 1)",
        n=7,
        gain=1.25 / 7,
        omega=(4.2568, 4.3143, 4.6691, 4.2951, 4.3623, 2.9433, 4.2184),
        assisted=5,
        duration=300.0,
    ),
    3: SyncGroup(
        name="Group 3 (Alderisio et al. 2017, group 2)",
        n=7,
        gain=4.4 / 7,
        omega=(2.7151, 2.9299, 4.0344, 2.1476, 3.9117, 3.7429, 3.2827),
        assisted=5,
        duration=300.0,
    ),
}

TABLE3_CHANGE_PCT: dict[int, float] = {1: 8.14, 2: 5.59, 3: 4.80}
"""Relative improvement (%) of the mean order parameter with L2 that the deliverable reports (Table 3),
keyed by Table 2's group numbers."""


def locking_gain(omega: Any, adjacency: Any) -> float:
    """Estimate of the gain above which the group can lock, from the spread of its frequencies.

    A locked group needs, for every set S of participants, the coupling across S's cut to carry
    S's frequency excess: ``K ≥ |Σ_{i∈S}(ω_i − ω̄)| / w(cut S)`` (weights symmetrised). The
    estimate is the largest such bound over the single participants and the sets of the k fastest
    (k = 1 … N − 1): a necessary condition, exact for two participants (``|ω_1 − ω_2| / 2``).
    Infinite for a graph that is not connected.
    """
    omega = np.asarray(omega, dtype=float)
    a = np.asarray(adjacency, dtype=float)
    a = (np.abs(a) + np.abs(a.T)) / 2.0
    excess = omega - omega.mean()
    n = len(omega)
    order = np.argsort(-excess)
    sets = [np.array([i]) for i in range(n)] + [order[:k] for k in range(1, n)]
    bound = 0.0
    for members in sets:
        inside = np.zeros(n, dtype=bool)
        inside[members] = True
        cut = a[inside][:, ~inside].sum()
        need = abs(excess[inside].sum())
        bound = max(bound, need / cut if cut > 0 else (math.inf if need > 0 else 0.0))
    return bound


#: Spawn keys of the generator's splits: a split's groups come from its own seed streams.
SPLITS: dict[str, int] = {"train": 0, "validation": 1, "test": 2}


#: Ranges of :func:`random_groups`' noise: σ_i log-uniform (rad/√s), drift spread uniform per participant
#: (fraction of abs(ω_i)), drift time constant uniform per group (s).
NOISE_RANGES: dict[str, tuple[float, float]] = {
    "sigma": (0.05, 0.5),
    "drift_spread": (0.05, 0.15),
    "drift_tau": (5.0, 20.0),
}


def _random_noise(rng: np.random.Generator, n: int) -> GroupNoise:
    low, high = NOISE_RANGES["sigma"]
    sigma = np.exp(rng.uniform(math.log(low), math.log(high), n))
    spread = rng.uniform(*NOISE_RANGES["drift_spread"], n)
    return GroupNoise(
        sigma=tuple(float(x) for x in sigma),
        drift_spread=tuple(float(x) for x in spread),
        drift_tau=float(rng.uniform(*NOISE_RANGES["drift_tau"])),
        seed=int(rng.integers(2**31)),
    )


def _random_group(rng: np.random.Generator, name: str) -> SyncGroup:
    n = int(rng.integers(3, 16))
    kind = ("ring", "all", "random")[int(rng.integers(3))]
    centre = rng.uniform(2.0, 7.0)
    spread = math.exp(rng.uniform(math.log(0.1), math.log(2.0)))
    omega = centre + spread * rng.standard_normal(n)
    graph: Any = kind
    if kind == "random":
        p = float(rng.uniform(0.2, 0.8))
        while True:  # redraw until connected: a split group has no locking gain to scale by
            graph = ("random", p, int(rng.integers(2**31)))
            if connected_components(adjacency_matrix(graph, n, sparse=True), directed=False)[0] == 1:
                break
    ratio = math.exp(rng.uniform(math.log(0.1), math.log(10.0)))
    gain = ratio * locking_gain(omega, adjacency_matrix(graph, n))
    duration = round(math.exp(rng.uniform(math.log(10.0), math.log(300.0))), 1)
    assisted = int(rng.integers(n))
    return SyncGroup(
        name=f"{name} ({kind}, K/K_c = {ratio:.2f})",
        n=n,
        gain=float(gain),
        omega=tuple(float(w) for w in omega),
        assisted=assisted,
        duration=duration,
        graph=graph,
    )


def random_groups(n: int, split: str = "train", seed: int = 0, *, noise: bool = False) -> list[SyncGroup]:
    """``n`` seeded random groups of one split, for training and held-out evaluation.

    Group ``i`` of a split is drawn from ``SeedSequence(seed, spawn_key=(SPLITS[split], i))``, so
    the splits never share a stream, and the first groups do not depend on ``n``. Distribution:

    * size N uniform in 3 … 15;
    * graph ring, all-to-all or random G(N, p) (p uniform in [0.2, 0.8], redrawn until
      connected), one third each;
    * ω_i = ω_c + σ z_i, z_i standard normal, ω_c uniform in [2, 7] rad/s, σ log-uniform in
      [0.1, 2] rad/s;
    * gain K = ρ K_c with K_c = :func:`locking_gain` of the frequencies on the graph and ρ
      log-uniform in [0.1, 10] (from far below to far above locking);
    * duration log-uniform in [10, 300] s (rounded to 0.1 s);
    * assisted participant uniform;
    * with ``noise``, a :class:`GroupNoise` from a stream of its own (``spawn_key=(split, i, 1)``), so that the
      noisy group ``i`` is the noise-free group ``i`` (drawn exactly as without ``noise``) plus noise:
      σ_i log-uniform in [0.05, 0.5] rad/√s, drift spread uniform in [5, 15] % of ``abs(ω_i)`` per participant,
      drift time constant uniform in [5, 20] s, and the noise's seed (:data:`NOISE_RANGES`).

    Parameters
    ----------
    n : int
        Number of groups, >= 0.
    split : {"train", "validation", "test"}
        Which split.
    seed : int
        Seed of the whole collection.
    noise : bool
        Give every group phase noise and frequency drift (noise-free groups by default).
    """
    if split not in SPLITS:
        raise ValueError(f"random_groups: split must be one of {sorted(SPLITS)}, got {split!r}")
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
        raise ValueError(f"random_groups: n must be an integer >= 0, got {n!r}")
    groups = []
    for i in range(int(n)):
        rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(SPLITS[split], i)))
        group = _random_group(rng, f"{split} group {i} (seed {seed})")
        if noise:
            noise_rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(SPLITS[split], i, 1)))
            group = dataclasses.replace(group, name=f"{group.name}, noisy", noise=_random_noise(noise_rng, group.n))
        groups.append(group)
    return groups
