"""The order parameter r of a group's phases: the synchronisation the L2 architecture raises."""

from __future__ import annotations

import math

import numpy as np

from cogblocks.sim import Block, Signal

__all__ = ["OrderParameter"]


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
