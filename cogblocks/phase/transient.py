"""The low-pass filter's transient after a drop-out, so that Algorithm 1 can remove it instead of waiting it out."""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np

from cogblocks.blocks.discrete import sos_step

__all__ = ["GapTransient"]


class GapTransient:
    """Response of a Butterworth low-pass (second-order sections) to what it missed during drop-outs.

    During a drop-out the filter in front of Algorithm 1 is fed the frozen value (``LowPass(gaps="repeat")``
    feeds the last finite value through missing samples too) instead of the movement. The filter is
    linear, so its output differs from the output it would have had on the movement by the filter's
    response, from rest, to ``e = movement − what it received``. Algorithm 1 feeds ``e`` (the oscillation
    it extrapolates, minus the frozen value) during a drop-out and 0 otherwise, and adds the response to
    the filtered position: the transient after the drop-out cancels as far as the extrapolation was right.

    Parameters
    ----------
    sos : sequence of (b0, b1, b2, a0, a1, a2)
        The filter's second-order sections, ``a0 = 1`` (``scipy.signal.butter(..., output="sos")``).
    """

    def __init__(self, sos: Sequence[Sequence[float]]) -> None:
        self.sos = [tuple(float(c) for c in section) for section in sos]

    def rest(self) -> np.ndarray:
        """The state at rest: one ``[z0, z1]`` row per section."""
        return np.zeros((len(self.sos), 2))

    def step(self, state: np.ndarray, e: float) -> tuple[float, np.ndarray]:
        """One sample of the response (transposed direct form II): ``(output, next state)``; ``state`` is kept."""
        nxt = np.empty_like(state)
        return sos_step(self.sos, state, e, nxt), nxt

    def run(self, state: np.ndarray, es: Iterable[float]) -> tuple[float, np.ndarray]:
        """Several samples from ``state``: the output of the last one and the state after it."""
        y = 0.0
        for e in es:
            y, state = self.step(state, e)
        return y, state
