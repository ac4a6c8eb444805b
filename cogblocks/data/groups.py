"""Kuramoto groups of the PoP of Social Connectedness (Table 2 of the deliverable, section 5.2.3.2).

Table 2 numbers the assisted participant from 1 (#4 in Group 1, #6 in Groups 2 and 3); here
``assisted`` is the 0-based index into ``omega`` (3 and 5). ``gain`` is Table 2's column ``c``
exactly as the simulation uses it (1.6, 1.25/7 and 4.4/7): it multiplies the coupling sum and is not
divided by N again. Group numbers follow Table 2, not Table 3 (whose rows are numbered differently).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["SyncGroup", "TABLE2", "TABLE3_CHANGE_PCT"]


@dataclass(frozen=True)
class SyncGroup:
    """Parameters of one simulated group (ring graph, all phases starting at 0 rad).

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
    """

    name: str
    n: int
    gain: float
    omega: tuple[float, ...]
    assisted: int
    duration: float

    def __post_init__(self) -> None:
        if len(self.omega) != self.n:
            raise ValueError(f"{self.name}: {len(self.omega)} frequencies for n = {self.n}")
        if not 0 <= self.assisted < self.n:
            raise ValueError(f"{self.name}: assisted index {self.assisted} outside 0..{self.n - 1}")


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
