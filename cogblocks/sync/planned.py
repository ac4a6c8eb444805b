"""The whole trial planned at once: the planner (:class:`~cogblocks.sync.receding.RecedingPlanMotion`), one decision.

:func:`whole_trial_plan` builds it: it does nothing (θ_ref = θ_L0) while
:class:`~cogblocks.sync.identification.KuramotoRLS` identifies the group's natural frequencies and coupling from the
observed phases; once the model is trusted it plans the alteration of every remaining tick of the trial on that
model with the search of the whole-run bound (the best reference rule from the predicted state, then the window
sweeps of :data:`~cogblocks.sync.sweeps.WHOLE_TRIAL_SWEEPS`, every step kept only if the predicted mean r to the
trial's end rises), and plays it open loop.

The plan is computed in one tick: about 0.3 s of CPU per second of trial (docs/validation/sync.md, "Every test run,
in one table"), so it is for simulated trials, not for live runs at 100 Hz, and it is only as good as the identified
model (ω to about 5e-5 rad/s after 1 s on a simulated group). The receding plan (``MOTIONS["replan"]``) re-plans
from the observed state every second instead.

:class:`PlannedMotion`, the same as a class of its own, is deprecated.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np

from cogblocks.sync.blending import BlenderParams
from cogblocks.sync.receding import RecedingPlanMotion
from cogblocks.sync.sweeps import WHOLE_TRIAL_SWEEPS, checked_sweeps

__all__ = ["SWEEPS", "PlannedMotion", "checked_sweeps", "whole_trial_plan"]

#: The sweeps of a whole-trial plan (the name :data:`~cogblocks.sync.sweeps.WHOLE_TRIAL_SWEEPS` had here).
SWEEPS = WHOLE_TRIAL_SWEEPS

#: What makes the planner plan the whole trial in one decision: no period, a plan and a first comparison of rules
#: to the trial's end, the model trusted after 100 increments (1 s), and a plan played whenever it is predicted better
#: than doing nothing.
WHOLE_TRIAL: dict[str, Any] = {"decide_every": None, "horizon": None, "compare": None, "min_ticks": 100, "margin": 0.0}


def whole_trial_plan(
    n: int,
    assisted: int,
    *,
    end: float,
    adjacency: Any = "ring",
    blender: BlenderParams | None = None,
    sweeps: Sequence[tuple[float, float, float]] = WHOLE_TRIAL_SWEEPS,
    **options: Any,
) -> RecedingPlanMotion:
    """The planner with one decision: the whole trial of ``end`` seconds planned at once (``MOTIONS["plan"]``).

    Parameters are :class:`~cogblocks.sync.receding.RecedingPlanMotion`'s; ``options`` may override
    :data:`WHOLE_TRIAL`'s ``min_ticks`` and ``margin`` and set any other of its keywords.
    """
    settings = {**WHOLE_TRIAL, **options}
    return RecedingPlanMotion(n, assisted, end=end, adjacency=adjacency, blender=blender, sweeps=sweeps, **settings)


class PlannedMotion(RecedingPlanMotion):
    """Deprecated: :func:`whole_trial_plan` builds the same planner (a :class:`RecedingPlanMotion`).

    Takes :func:`whole_trial_plan`'s keywords and keeps the old records ``plan`` (the planned alterations, rad),
    ``plan_ms`` and ``predicted``, for one release.
    """

    def __init__(self, n: int, assisted: int, *, end: float, **options: Any) -> None:
        settings = {"sweeps": WHOLE_TRIAL_SWEEPS, **WHOLE_TRIAL, **options}
        super().__init__(n, assisted, end=end, **settings)
        warnings.warn(
            "PlannedMotion is deprecated: whole_trial_plan(n, assisted, end=...) (cogblocks.sync.planned) builds the "
            "same plan as a RecedingPlanMotion with decide_every=None",
            DeprecationWarning,
            stacklevel=2,
        )

    @property
    def plan(self) -> np.ndarray | None:
        """The planned alteration (rad) of ticks ``plan_start``, ``plan_start + 1``, …, or ``None`` before it."""
        return self.plan_a

    @property
    def plan_ms(self) -> float | None:
        """CPU time (ms) the plan took."""
        return self.decide_ms[0] if self.decide_ms else None

    @property
    def predicted(self) -> np.ndarray | None:
        """The plan's predicted r of every planned tick, on the identified model."""
        return self.plans[0][2] if self.plans else None
