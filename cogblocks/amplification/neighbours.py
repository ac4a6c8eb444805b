"""The human's prediction from several library movements: the mean of the ``k`` nearest to the measured prefix.

:class:`~cogblocks.amplification.OptimalBlender` plans on a prediction of the human's future. With one
neighbour it is η_i, the projector's nearest movement of the class not encoding ``e_des``. A human nobody
tuned on reaches its end by a path no single library movement follows; averaging the ``k`` nearest
movements of the whole library (both classes: the prediction is of the motion, not of its class) cuts the
error of the predicted end point at the last decision where it is large (mean over the movements ending beyond
20 mm: 17–22 mm with η_i, 11–17 mm with 5; docs/validation/amplification.md).

The distance is the projector's (:class:`~cogblocks.amplification.projector.PrefixProjection`, mean
Euclidean distance of the velocity prefixes) kept as running sums in the blender's state, one sample per
tick, so a decision costs a sort of the library, not a pass over its prefixes.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from cogblocks.amplification.projector import PrefixProjection
from cogblocks.data.reach import ReachLibrary
from cogblocks.sim.params import positive_int

__all__ = ["NeighbourPrediction"]


class NeighbourPrediction:
    """The mean velocity of the ``k`` library movements nearest to a growing human prefix.

    Parameters
    ----------
    owner : object
        Named in the error for a bad ``k``.
    library : ReachLibrary
        The movements the neighbours are taken from.
    k : int
        Neighbours averaged, 1 … ``len(library)``.
    """

    def __init__(self, owner: Any, library: ReachLibrary, k: int) -> None:
        self.k = positive_int(owner, "neighbours", k)
        if self.k > len(library):
            name = owner if isinstance(owner, str) else type(owner).__name__
            raise ValueError(f"{name}: neighbours must be at most the library's {len(library)} movements, got {k}")
        self.velocity = library.velocity
        self._projection = PrefixProjection(library.velocity, metric="mean", dtype="float64", block=1)

    def declare(self, block: Any) -> None:
        """Add the running distances (``neighbour_sums``, one per movement) to ``block``'s state, if ``k`` > 1."""
        if self.k > 1:
            block.add_state("neighbour_sums", np.zeros(len(self.velocity)))

    def record(self, block: Any, t: int) -> None:
        """Add ``block.human[t]``, the sample just recorded, to its running distances (nothing if ``k`` = 1)."""
        if self.k > 1:
            self._projection.accumulate(block.neighbour_sums, block.human[t : t + 1], t)

    def nearest(self, sums: np.ndarray) -> np.ndarray:
        """Indices of the ``k`` movements with the smallest ``sums``, nearest first (ties by index)."""
        return np.argsort(sums, kind="stable")[: self.k]

    def basis(self, block: Any, nearest: int) -> np.ndarray:
        """The velocity (T, 3) the prediction follows: movement ``nearest`` (η_i) if ``k`` = 1, else the mean of the
        ``k`` movements nearest to the samples ``block`` has recorded."""
        if self.k == 1:
            return self.velocity[nearest]
        return self.velocity[self.nearest(block.neighbour_sums)].mean(axis=0)
