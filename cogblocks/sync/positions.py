"""Arm positions of a group from its phases: the position domain of the PoP of Social Connectedness."""

from __future__ import annotations

from typing import Any

import numpy as np

from cogblocks.sim import Block, Signal
from cogblocks.sim.params import finite_array, finite_number, positive_int, random_generator

__all__ = ["ArmPositions"]


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
