"""Motion computers that decide every period on the group model they identify online, and that model's prediction.

:class:`PeriodicIdentifyingMotion` is what the pacing rule (:class:`~cogblocks.sync.pacing.PacingMotion`) and the
shield around any motion computer (:class:`~cogblocks.sync.shielded.ShieldedMotion`) share: the group identified
from the observed phases, the trust in that model, and the decision period; each adds its own decision.
:func:`euler_step` advances the identified group, with the blender's λ in the loop, for several candidate references
at once, and :func:`margin_choice` picks among their predicted scores against doing nothing; both decisions use them.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from cogblocks.blocks.angles import wrap_pi
from cogblocks.sim.params import finite_number, positive_int
from cogblocks.sync.blending import BlenderParams, lam_step
from cogblocks.sync.identification import usable_phases
from cogblocks.sync.motion import _IdentifyingMotion
from cogblocks.sync.periods import block_step, decision_period, period_ticks

__all__ = ["MEAN", "NONE", "PACE", "PeriodicIdentifyingMotion", "euler_step", "margin_choice"]

#: Candidate kinds of :func:`euler_step`: leave θ_L0 unaltered, follow the others' circular mean, pace at a constant
#: frequency from an anchor (at frequency 0: hold the anchor as the reference).
NONE, MEAN, PACE = 0, 1, 2


def euler_step(
    theta: np.ndarray,
    lam: np.ndarray,
    model: tuple[np.ndarray, float],
    adjacency: np.ndarray,
    assisted: int,
    blender: BlenderParams,
    candidates: tuple[np.ndarray, np.ndarray, np.ndarray],
    elapsed: float,
    step: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One Euler step of :func:`~cogblocks.sync.pacing.predicted_order` for every candidate (one row each).

    ``theta`` (C, N) and ``lam`` (C,) are the state ``elapsed`` seconds after the candidates' start; returns
    the state ``step`` seconds later and the order parameter of the phases seen now (θ_L2 substituted), (C,).
    The candidates are as for :func:`~cogblocks.sync.pacing.predicted_order`.
    """
    kinds, values, anchors = candidates
    omega, gain = model
    n = theta.shape[1]
    others = np.arange(n) != assisted
    pace, mean = kinds == PACE, kinds == MEAN
    sin, cos = np.sin(theta), np.cos(theta)
    l0 = theta[:, assisted]
    d = np.where(pace, wrap_pi(anchors + values * elapsed - l0), 0.0)
    if mean.any():
        to_mean = wrap_pi(np.arctan2(sin[:, others].sum(axis=1), cos[:, others].sum(axis=1)) - l0)
        d = np.where(mean & (np.abs(to_mean) <= values), to_mean, d)
    shift = np.clip(d, -lam, lam)
    sin[:, assisted], cos[:, assisted] = np.sin(l0 + shift), np.cos(l0 + shift)
    r = np.hypot(sin.sum(axis=1), cos.sum(axis=1)) / n
    # eq. (5)-(6): λ relaxes toward λ∞(e), fast down (κ⁻), slow up (κ⁺)
    lam = lam_step(lam, shift, blender, step)
    # Σ_j a_ij sin(θ̃_j − θ̃_i) = cos θ̃_i (A sin θ̃)_i − sin θ̃_i (A cos θ̃)_i
    pull = cos * (sin @ adjacency.T) - sin * (cos @ adjacency.T)
    return theta + step * (omega + gain * pull), lam, r


def margin_choice(kinds: np.ndarray, scores: np.ndarray, current: int, margin: float, switch_margin: float) -> int:
    """The best-scored candidate, kept only if it beats the current one by ``switch_margin`` and *none* by ``margin``.

    ``kinds[0]`` must be :data:`NONE`: the result is 0 or a candidate whose predicted mean r is at least
    ``scores[0] + margin``, so a candidate predicted to lower r against doing nothing is never chosen.
    """
    best = int(np.argmax(scores))
    if scores[best] < scores[current] + switch_margin:
        best = current
    if kinds[best] != NONE and scores[best] < scores[0] + margin:
        best = 0
    return best


class PeriodicIdentifyingMotion(_IdentifyingMotion):
    """A motion computer that identifies the group online and decides every period on the model once it is trusted.

    The ports and what every identifying motion computer shares come from
    :class:`~cogblocks.sync.motion._IdentifyingMotion`; on top of them:

    * the identification (:meth:`_identify`): every good tick's increment goes to the least squares, on θ̃, the
      phases with θ_L2 rebuilt from the reference the block emitted and the λ it received (no oracle); the phases
      of the last tick are block state (``previous``, NaN after a bad tick, so that no increment ending or starting
      at one is identified);
    * the trust (:meth:`model`): the identified ``(ω, K)`` once ``min_ticks`` increments are in and the information
      on the gain (:meth:`KuramotoRLS.gain_excitation <cogblocks.sync.identification.KuramotoRLS.gain_excitation>`)
      reaches ``min_excitation``;
    * the period: ``decide_every`` seconds, counted in ticks (``decide_ticks``) of the block's step when the diagram
      is compiled; ``due`` (block state) marks a decision due at the next good tick;
    * the prediction's Euler step (:meth:`_stable_step`): ``step``, shortened where the identified coupling needs it
      for stability (``step · K · max_i Σ_j a_ij ≤ 0.5``).

    Parameters
    ----------
    n, assisted, period, adjacency, blender
        As for :class:`~cogblocks.sync.motion._IdentifyingMotion`.
    decide_every : float
        Seconds per period, a whole number of the block's steps.
    step : float
        Largest Euler step (s) of the prediction.
    min_ticks : int
        Observed increments before the model is trusted.
    min_excitation : float
        Information on the gain (the least squares' Schur complement) before the model is trusted.
    """

    def __init__(
        self,
        n: int,
        assisted: int,
        period: float | None,
        adjacency: Any,
        blender: Any,
        *,
        decide_every: float,
        step: float = 0.05,
        min_ticks: int = 100,
        min_excitation: float = 1.0,
    ) -> None:
        super().__init__(n, assisted, period, adjacency, blender)
        # stacklevel 4: the warning names the line that calls the subclass's constructor, where decide_every was given
        self.decide_every, self._given_ticks = decision_period(self, decide_every, stacklevel=4)
        self.decide_ticks = period_ticks(self, self.decide_every, self._given_ticks)  # counted again when compiled
        self.step = finite_number(self, "step", step, low=0.0, low_open=True)
        self.min_ticks = positive_int(self, "min_ticks", min_ticks, minimum=1)
        self.min_excitation = finite_number(self, "min_excitation", min_excitation, low=0.0)
        self.add_state("due", True)
        self.add_state("previous", np.full(2 * n, math.nan))  # θ̃ and own phases of the last tick (NaN: bad)

    @property
    def decision_period(self) -> float:
        """Seconds between decisions: ``decide_ticks`` ticks of the block's step."""
        return self.decide_ticks * block_step(self)

    def setup(self) -> None:
        super().setup()
        try:
            self.decide_ticks = period_ticks(self, self.decide_every, self._given_ticks)
        except ValueError as exc:
            raise self._fail(str(exc).removeprefix(f"{type(self).__name__}: ")) from None

    def model(self) -> tuple[np.ndarray, float] | None:
        """The identified ``(ω, K)``, or ``None`` while it is not trusted."""
        rls = self.identifier()
        if self.count < self.min_ticks or rls.gain_excitation() < self.min_excitation:
            return None
        omega, gain = rls.estimate()
        return (omega, gain) if np.isfinite(omega).all() and math.isfinite(gain) else None

    def _identify(self, theta: np.ndarray, lam: float, ref: float, dt: float) -> np.ndarray:
        """Add this tick's increment to the least squares; returns θ̃ (θ_L2 rebuilt from the reference and λ)."""
        l0 = theta[self.assisted]
        seen = theta.copy()
        seen[self.assisted] = l0 + min(max(float(wrap_pi(ref - l0)), -lam), lam)
        if usable_phases(self.previous) and self.identifier().observe(
            self.previous[: self.n], self.previous[self.n :], theta, dt
        ):
            self.count += 1
        self.previous[: self.n], self.previous[self.n :] = seen, theta
        return seen

    def _stable_step(self, gain: float) -> float:
        """The prediction's Euler step: ``step``, shortened where the identified coupling would make it unstable."""
        stiffness = abs(gain) * float(np.abs(self.adjacency).sum(axis=1).max())
        return 0.5 / stiffness if stiffness * self.step > 0.5 else self.step
