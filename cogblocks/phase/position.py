"""Phase → position (section 6): the point of a reference cycle at a given phase."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from cogblocks.blocks.angles import TWO_PI
from cogblocks.blocks.specs import POSITION
from cogblocks.phase.customizer import _as_curve
from cogblocks.sim import Block, Signal
from cogblocks.sim.params import finite_number, random_generator

__all__ = ["PhasePositionComputer"]


class PhasePositionComputer(Block):
    """Position on the reference motion for a phase (section 6.2, Figure 15).

    ``i = round(N θ / 2π) mod N`` (halves rounded up) and ``p = γ_ref(i)``, plus optional white
    Gaussian noise of standard deviation ``noise_std`` per axis, to make the motion look human.

    Ports
    -----
    theta : input, rad (wrapped or not)
        Phase.
    reference : input, shape (N, 3), mm, optional
        The reference motion, for a time-varying one (for instance a customised reference of N
        samples); unconnected, it is the constant ``reference`` given to the constructor.
    p : output, shape (3,), mm
        Position.

    Parameters
    ----------
    reference : array_like, shape (N, 3)
        The reference motion γ_ref, one cycle from phase 0, in mm (N >= 1). Fixes N.
    noise_std : float
        Standard deviation of the added noise in mm (>= 0; 0 by default).
    seed : int or numpy.random.Generator, optional
        Seed of the noise. The generator is part of the block's state, so ``reset()`` and
        ``load_state_dict()`` replay the same noise.

    Notes
    -----
    Bad data policy: a non-finite phase, or a non-finite element in the reference sample it
    selects, holds the last position (the reference may come from an upstream estimate).
    """

    def __init__(
        self,
        reference: Any,
        *,
        noise_std: float = 0.0,
        seed: int | np.random.Generator | None = None,
        period: float | None = None,
    ) -> None:
        super().__init__(period=period)
        ref = _as_curve("PhasePositionComputer", "reference", reference, 1)
        self.n_samples = len(ref)
        self.noise_std = finite_number(self, "noise_std", noise_std, low=0.0)
        self.add_input("theta", Signal(unit="rad", wrapped=None))
        self.add_input("reference", shape=ref.shape, unit="mm", default=ref)
        self.add_output("p", POSITION, initial=ref[0])
        rng = random_generator(self, "seed", seed)
        # the noise of a tick is drawn in the previous tick's update, so output() leaves the state alone
        self.add_state("noise", self._draw(rng))
        self.add_state("rng", rng)

    def _draw(self, rng: np.random.Generator) -> np.ndarray:
        return rng.normal(scale=self.noise_std, size=3) if self.noise_std > 0 else np.zeros(3)

    def output(self, k: int) -> None:
        theta = float(self.theta.value)
        if not math.isfinite(theta):
            return
        i = math.floor(self.n_samples * theta / TWO_PI + 0.5) % self.n_samples
        sample = self.reference.value[i]
        if np.isfinite(sample).all():
            np.add(sample, self.noise, out=self.p.value)

    def update(self, k: int) -> None:
        self.noise = self._draw(self.rng)
