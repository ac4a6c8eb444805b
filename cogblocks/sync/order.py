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

    Runs a batch at once (each run's r from its own phases; the modulus is NumPy's ``hypot``
    there for more than one run, which may differ from one run's ``math.hypot`` in the last bit).
    """

    batchable = True

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
        if self.batch is not None:
            self._output_rows(theta)
            return
        if not math.isfinite(np.add.reduce(theta)):  # one cheap check keeps cos/sin off inf and NaN
            theta = theta[np.isfinite(theta)]
            if theta.size == 0:
                return
        self.r.value[...] = math.hypot(np.add.reduce(np.cos(theta)), np.add.reduce(np.sin(theta))) / theta.size

    def _output_rows(self, theta: np.ndarray) -> None:
        if math.isfinite(np.add.reduce(theta, axis=None)):  # one cheap check for the whole batch
            c, s = np.add.reduce(np.cos(theta), axis=-1), np.add.reduce(np.sin(theta), axis=-1)
            if self.batch == 1:  # a batch of one is the unbatched run to the bit
                self.r.value[...] = math.hypot(c[0], s[0]) / self._n
            else:
                np.divide(np.hypot(c, s), self._n, out=self.r.value)
            return
        finite = np.isfinite(theta)
        with np.errstate(invalid="ignore"):
            c = np.add.reduce(np.where(finite, np.cos(theta), 0.0), axis=-1)
            s = np.add.reduce(np.where(finite, np.sin(theta), 0.0), axis=-1)
        count = finite.sum(axis=-1)
        np.copyto(self.r.value, np.hypot(c, s) / np.maximum(count, 1), where=count > 0)
