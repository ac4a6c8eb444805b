"""Real-time iteration: a spread solve of :class:`~cogblocks.amplification.OptimalBlender` follows the past.

A decision at tick ``T`` plans from ``t0 = T + solve_ticks − 1`` on, for a past in which, on ``T … t0 − 1``,
the human follows the prediction and the state in force emits on it; the plan is committed at ``t0``. The
past actually emitted there (the measured human, and the state in force on it) differs, so a plan accepted
on its problem can fail its constraints on the movement it is committed into (docs/validation/amplification.md).
With ``track_past``, every tick of the solve replaces in the problem the prediction of the
ticks emitted since by what was measured and emitted (:func:`~cogblocks.amplification.plan.with_past`:
the knots act from ``t0`` on, so only the problem's fixed part changes) and the iterations continue from
the current iterate (:meth:`~cogblocks.amplification.linearised.LinearisedRun.update`); at the commit the
problem is that of the true past, and so is the kept plan's acceptance.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from cogblocks.amplification.emission import planned_movement
from cogblocks.amplification.plan import with_past

__all__ = ["follow_past", "past_so_far"]


def past_so_far(
    t: int, predicted: np.ndarray, altered: np.ndarray, human: np.ndarray, state: dict[str, Any],
    reference: np.ndarray, emit: str,
) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """The emitted and the human velocity a solve assumes at tick ``t``: the records before ``t``, then
    ``predicted`` followed by the human and emitted under ``state`` (``reference``: the table's blend)."""
    emitted = planned_movement(t, altered, predicted, state, reference, emit)
    return emitted, np.concatenate([human[:t], predicted[t:]])


def follow_past(blender: Any, job: dict[str, Any], t: int) -> None:
    """Put the past emitted before tick ``t`` into ``job``'s problem and its run (``blender``: an OptimalBlender).

    ``job`` is the blender's decision in flight (``t0``, ``length``, ``predicted``, ``reference``,
    ``problem``, ``run``); the state in force is the one the ticks since the decision emitted.
    """
    reference = blender.library.velocity[job["reference"]]
    altered, human = past_so_far(
        t, job["predicted"], blender.altered, blender.human, blender._in_force(), reference, blender.emit
    )
    job["problem"] = with_past(
        job["problem"], job["t0"], job["length"], job["predicted"], altered, human, reference, blender.dt,
        [blender._sign, blender._z_target, blender.end_speed, blender._delta], blender.subspace, blender.realism,
    )  # fmt: skip
    job["run"].update(job["problem"])
