"""A prediction of the group's order parameter run a few Euler steps per tick instead of all at once.

:func:`~cogblocks.sync.pacing.predicted_order` simulates every candidate over the whole horizon in one call
(tens of milliseconds, several 10 ms ticks). :class:`StagedPrediction` runs the same Euler steps
(:func:`~cogblocks.sync.identified.euler_step`) in two stages, a bounded number of steps per call:

1. the *lead*: one trajectory under the reference being emitted now, for one decision period: it predicts the
   state the group will be in when the decision applies (and, compared with what is then observed, how well
   the model predicts);
2. the *fan-out*: from the lead's end, every candidate over the horizon, as :func:`predicted_order` scores them.

A decision started at one period's first tick is then ready at the next period's first tick, with a cost
per tick of ``ceil(total steps / period ticks)`` Euler steps over at most the number of candidates.

What a prediction has computed so far is plain arrays and a count (:meth:`StagedPrediction.progress`), so that a
block can keep it as declared state and resume it after a snapshot (:meth:`StagedPrediction.resume`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from cogblocks.sync.identified import euler_step
from cogblocks.sync.model import BlenderParams

__all__ = ["PROGRESS", "StagedPrediction"]

Candidates = tuple[np.ndarray, np.ndarray, np.ndarray]

#: Names of what :meth:`StagedPrediction.progress` returns: everything an advance changes.
PROGRESS = ("theta", "lam", "kinds", "values", "anchors", "total", "early", "lead_theta", "done_steps")


class StagedPrediction:
    """The lead and the fan-out of one decision, advanced a bounded number of Euler steps at a time.

    Parameters
    ----------
    theta : ndarray, shape (N,)
        The participants' phases at the start.
    lam : float
        The blender's λ at the start.
    model, adjacency, assisted, blender
        As for :func:`~cogblocks.sync.pacing.predicted_order`.
    lead : (kind, value, anchor)
        The reference emitted during the lead (one candidate, anchored at the start).
    lead_time : float
        Duration (s) of the lead, in ``lead_steps`` equal Euler steps.
    lead_steps : int
        Euler steps of the lead.
    fan_out : callable
        ``fan_out(theta, lam) -> (kinds, values, anchors)``: the candidates, anchored at the lead's end, from
        the predicted state there. A bound method of a block rather than a closure, if the block is to be
        copied or resumed from a snapshot: what it needs must be in the block's state.
    step : float
        Euler step (s) of the fan-out.
    steps : int
        Euler steps of the fan-out; the scores are the mean r over them.
    checkpoint : int, optional
        Also keep every candidate's mean r over the fan-out's first ``checkpoint`` steps (at most ``steps``):
        :attr:`early_scores`.

    Attributes
    ----------
    evaluations : int
        Candidate-steps done by the last :meth:`advance` (rows × Euler steps): its cost.
    """

    def __init__(
        self,
        theta: np.ndarray,
        lam: float,
        model: tuple[np.ndarray, float],
        adjacency: np.ndarray,
        assisted: int,
        blender: BlenderParams,
        lead: tuple[float, float, float],
        *,
        lead_time: float,
        lead_steps: int,
        fan_out: Callable[[np.ndarray, float], Candidates],
        step: float,
        steps: int,
        checkpoint: int | None = None,
    ) -> None:
        self.model, self.adjacency, self.assisted, self.blender = model, adjacency, assisted, blender
        self.theta = np.asarray(theta, dtype=float)[None, :].copy()
        self.lam = np.array([float(lam)])
        self.rows: Candidates = tuple(np.array([float(v)]) for v in lead)
        self.lead_step, self.lead_steps = lead_time / lead_steps, lead_steps
        self.fan_out, self.step, self.steps = fan_out, step, steps
        self.checkpoint = None if checkpoint is None else max(1, min(int(checkpoint), steps))
        self.done_steps = 0  # of lead_steps + steps
        self.lead_theta: np.ndarray | None = None  # the predicted phases at the lead's end
        self.candidates: Candidates | None = None
        self.total = np.zeros(0)
        self.early = np.zeros(0)  # the totals at the checkpoint, once the fan-out has passed it
        self.evaluations = 0

    @property
    def total_steps(self) -> int:
        """Euler steps of the whole prediction (lead and fan-out)."""
        return self.lead_steps + self.steps

    @property
    def done(self) -> bool:
        return self.done_steps >= self.total_steps

    @property
    def scores(self) -> np.ndarray:
        """The predicted mean r of every candidate over the fan-out (once :attr:`done`)."""
        if not self.done:
            raise RuntimeError("StagedPrediction: the scores are known only once every step is done")
        return self.total / self.steps

    @property
    def early_scores(self) -> np.ndarray:
        """The predicted mean r of every candidate over the fan-out's first ``checkpoint`` steps (once :attr:`done`)."""
        if self.checkpoint is None:
            raise RuntimeError("StagedPrediction: no checkpoint was asked for")
        if not self.done:
            raise RuntimeError("StagedPrediction: the scores are known only once every step is done")
        return self.early / self.checkpoint

    def advance(self, budget: int) -> None:
        """Run at most ``budget`` Euler steps (stopping when done)."""
        self.evaluations = 0
        for _ in range(budget):
            if self.done:
                return
            lead = self.done_steps < self.lead_steps
            s = self.done_steps if lead else self.done_steps - self.lead_steps
            step = self.lead_step if lead else self.step
            self.theta, self.lam, r = euler_step(
                self.theta, self.lam, self.model, self.adjacency, self.assisted, self.blender, self.rows, s * step, step
            )
            self.evaluations += len(self.lam)
            if not lead:
                self.total += r
                if s + 1 == self.checkpoint:
                    self.early = self.total.copy()
            self.done_steps += 1
            if self.done_steps == self.lead_steps:
                self._fan_out()

    def progress(self) -> dict[str, np.ndarray | int]:
        """What the prediction has computed so far (no copy), by the names of :data:`PROGRESS`.

        ``theta`` (rows, N), ``lam``, ``kinds``, ``values``, ``anchors`` and ``total`` (rows,) are the rows being
        predicted (the lead's one row, then the candidates), ``early`` the totals at the checkpoint (empty before
        it), ``lead_theta`` (N,) the phases at the lead's end (NaN before it), ``done_steps`` the Euler steps done.
        """
        kinds, values, anchors = self.rows
        lead_theta = np.full(self.theta.shape[1], np.nan) if self.lead_theta is None else self.lead_theta
        return {
            "theta": self.theta,
            "lam": self.lam,
            "kinds": kinds,
            "values": values,
            "anchors": anchors,
            "total": self.total,
            "early": self.early,
            "lead_theta": lead_theta,
            "done_steps": self.done_steps,
        }

    def resume(self, progress: Mapping[str, Any]) -> None:
        """Continue from what :meth:`progress` returned, on a prediction started with the same arguments.

        The arrays are copied: the prediction then advances on its own, as the one it was taken from would.
        """
        names = ("theta", "lam", "total", "early")
        self.theta, self.lam, self.total, self.early = (np.array(progress[name], dtype=float) for name in names)
        self.rows = tuple(np.array(progress[name], dtype=float) for name in ("kinds", "values", "anchors"))
        self.done_steps = int(progress["done_steps"])
        fanned_out = self.done_steps >= self.lead_steps
        self.lead_theta = np.array(progress["lead_theta"], dtype=float) if fanned_out else None
        self.candidates = self.rows if fanned_out else None

    def _fan_out(self) -> None:
        self.lead_theta = self.theta[0].copy()
        self.candidates = tuple(np.asarray(c, dtype=float) for c in self.fan_out(self.lead_theta, float(self.lam[0])))
        count = len(self.candidates[0])
        self.theta = np.tile(self.lead_theta, (count, 1))
        self.lam = np.full(count, self.lam[0])
        self.rows = self.candidates
        self.total, self.early = np.zeros(count), np.zeros(0)
