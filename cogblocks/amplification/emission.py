"""What :class:`~cogblocks.amplification.OptimalBlender` emits between decisions, and the terminal guard.

A plan is the predicted human ``b`` (the projector's nearest library movement when the plan was made)
plus a correction ``u``; it is checked on ``b + u``. Two ways to emit it:

- ``"human"``: the measured human plus the correction, ``v_h + u``. The terminal gap is ``dt·Σ u``
  whatever the human does, but the emitted movement is not the checked one: the prediction's error
  enters it between a decision and its commit and after the last commit (docs/validation/amplification.md).
- ``"plan"``: the plan itself, ``b + u``, so that the emitted movement is the movement planned and
  checked. The terminal gap then drifts by ``dt·Σ (b − v_h)``; the next decision sees the drift and
  plans it away, and a **guard** covers the ticks until then (:func:`guarded_velocity`): when the final
  gap the plan now leads to (the human following ``b``) exceeds ``δ_pos`` (the bound a plan is accepted
  with), the excess is taken back evenly over the ticks left to the plan's end, so it is within
  ``δ_pos`` at the end and the emitted velocity changes by small steps, not by the prediction's error.

- ``"tail"``: ``v_h + u``, except a plan committed within ``knot_spacing`` samples of its end (with decisions
  every ``knot_spacing`` samples, the last one), emitted as ``b + u`` under the guard: the movement after the
  last commit is the checked one, and the terminal gap takes the prediction's error over that tail only
  (docs/validation/amplification.md). The state in force says which (``as_planned``).

The guard's options (:func:`guard_settings`, docs/validation/amplification.md): ``guard_rest``, a human
measured at rest is predicted to stay at rest (as a decision predicts it), so that the guard sees the gap the plan's
movement opens after the human has stopped; ``guard_margin``, the gap is bounded at ``δ_pos − guard_margin``.

Emitting the plan, a committed plan is also **re-anchored** (:func:`rebased`): its held correction is
taken from the sample actually emitted before it, not the one its problem assumed (they differ after the
pass-through or the guard), so that the emitted velocity stays continuous; its check is made after that.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from cogblocks.amplification.blending import blend
from cogblocks.amplification.plan import equivalent_c
from cogblocks.sim.params import finite_number, flag

__all__ = [
    "EMISSIONS",
    "as_planned",
    "emit_tick",
    "final_gap",
    "guard_settings",
    "guarded_velocity",
    "planned_movement",
    "rebased",
]

#: The values of ``OptimalBlender(emit=...)``.
EMISSIONS = ("human", "plan", "tail")


def as_planned(state: dict[str, Any], emit: str) -> bool:
    """Whether the plan in force under ``state`` is emitted as planned (``b + u``) rather than as ``v_h + u``."""
    return emit == "plan" or (emit == "tail" and bool(state.get("as_planned", 0)))


def guard_settings(block: Any, guard_rest: bool, guard_margin: float) -> tuple[bool, float, float, float | None]:
    """The options ``guard_rest`` and ``guard_margin`` checked, then the guard's bound (mm) and rest speed.

    ``block`` has ``delta_pos`` and ``rest_speed``; ``guard_margin`` must lie in ``[0, delta_pos)``. The rest
    speed is None without ``guard_rest`` (the guard follows the prediction throughout). Raises ValueError, naming
    ``block``, for a value out of range or not of its type.
    """
    rest = flag(block, "guard_rest", guard_rest)
    margin = finite_number(block, "guard_margin", guard_margin, low=0.0, high=block.delta_pos, high_open=True)
    return rest, margin, block.delta_pos - margin, block.rest_speed if rest else None


def emit_tick(
    t: int, v_h: np.ndarray, v_r: np.ndarray, v_a: np.ndarray, state: dict[str, Any], altered: np.ndarray,
    human: np.ndarray, dt: float, emit: str, bound: float, rest_speed: float | None = None,
) -> tuple[float, bool]:  # fmt: skip
    """Write tick ``t``'s velocity under ``state`` (the block's state in force) into ``v_a``, before any ``v_u``.

    The plan (``v_h + u``, or the guarded ``b + u`` when :func:`as_planned`, the guard's ``bound`` and
    ``rest_speed`` those of :func:`guarded_velocity`; zero from its end on), else the table's blend, else ``v_h``.
    Returns the diagnostic ``c`` and whether the guard changed the velocity.
    """
    if state["end"] > 0 and as_planned(state, emit) and t < state["end"]:
        v_a[...], guarded = guarded_velocity(
            t, v_h, altered, human, state["plan"], state["basis"], state["end"], dt, bound, rest_speed
        )
        return equivalent_c(v_a, v_h, v_r), guarded
    if state["end"] > 0:
        v_a[...] = v_h + state["plan"][t] if t < state["end"] else 0.0
        return equivalent_c(v_a, v_h, v_r), False
    if math.isfinite(state["table_c"]):
        blend(state["table_c"], v_h, v_r, v_a)
        return state["table_c"], False
    v_a[...] = v_h
    return 1.0, False


def planned_movement(
    t: int, altered: np.ndarray, predicted: np.ndarray, state: dict[str, Any], reference: np.ndarray, emit: str
) -> np.ndarray:
    """The movement emitted under ``state`` (``altered`` before ``t``, then from ``t`` on) if the human follows
    ``predicted``; ``reference`` is the reference movement's velocity (for the table's blend)."""
    future = predicted[t:]
    if state["end"] > 0:  # emitting the plan, the future is its own prediction's, not this one's
        future = (state["basis"][t:] if as_planned(state, emit) else future) + state["plan"][t:]
        future[max(state["end"] - t, 0) :] = 0.0
    elif math.isfinite(state["table_c"]):
        c = state["table_c"]
        future = c * future + (1.0 - c) * reference[t : len(predicted)]
    return np.concatenate([altered[:t], future])


def final_gap(
    t: int, v_a: np.ndarray, v_h: np.ndarray, altered: np.ndarray, human: np.ndarray,
    plan: np.ndarray, basis: np.ndarray, end: int, dt: float, at_rest: bool = False,
) -> np.ndarray:  # fmt: skip
    """The final position gap ``p_a − p_h`` (mm) if tick ``t`` emits ``v_a`` and then the plan is emitted
    while the human follows its basis (``at_rest``: stays at rest).

    Parameters
    ----------
    t : int
        The tick; ``altered[:t]`` and ``human[:t]`` are what was emitted and measured before it.
    v_a, v_h : numpy.ndarray, shape (3,)
        This tick's emitted and measured velocity.
    altered, human, plan, basis : numpy.ndarray, shape (T, 3)
        The block's records, the correction in force and the prediction it was planned on.
    end : int
        The planned length: the block emits zero from it on, while the human (as predicted) may still move.
    dt : float
        Sampling step in seconds.
    at_rest : bool
        The human does not move after ``t``, while the plan (``basis + plan``) is emitted until ``end``.
    """
    if at_rest:
        rest = (plan[t + 1 : end] + basis[t + 1 : end]).sum(axis=0)
    else:  # the human follows the basis: only the correction differs before the end
        rest = plan[t + 1 : end].sum(axis=0) - basis[max(end, t + 1) :].sum(axis=0)
    return dt * ((altered[:t] - human[:t]).sum(axis=0) + v_a - v_h + rest)


def guarded_velocity(
    t: int, v_h: np.ndarray, altered: np.ndarray, human: np.ndarray,
    plan: np.ndarray, basis: np.ndarray, end: int, dt: float, delta: float, rest_speed: float | None = None,
) -> tuple[np.ndarray, bool]:  # fmt: skip
    """This tick's velocity under ``emit="plan"`` (``t < end``) and whether the guard corrected it.

    ``b + u`` if its :func:`final_gap` ``G`` is within ``delta`` (mm); otherwise ``b + u − e / (dt·(end − t))``
    with ``e = G·(1 − delta/‖G‖)`` the excess: spread over the ticks left, so that, the human following
    ``b``, the final gap is ``delta`` after the last one. With ``rest_speed``, ``G`` assumes a human whose
    ``‖v_h‖`` is at or below it stays at rest (the human then staying so, the final gap is ``delta`` too).
    A non-finite ``v_h`` gives ``v_h + u`` (non-finite: the block's bad data policy).
    """
    planned = basis[t] + plan[t]
    if not np.all(np.isfinite(v_h)):
        return v_h + plan[t], True
    at_rest = rest_speed is not None and float(np.linalg.norm(v_h)) <= rest_speed
    gap = final_gap(t, planned, v_h, altered, human, plan, basis, end, dt, at_rest)
    size = float(np.linalg.norm(gap))
    if size <= delta:
        return planned, False
    return planned - gap * (1.0 - delta / size) / (dt * (end - t)), True


def rebased(
    plan: np.ndarray, basis: np.ndarray, predicted: np.ndarray, t0: int, phi0: np.ndarray,
    held: np.ndarray, emitted: np.ndarray | None, anchor: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """The correction and basis to commit for a plan from ``t0`` when the block emits the plan.

    Parameters
    ----------
    plan : numpy.ndarray, shape (T, 3)
        The correction with the new plan from ``t0`` on (modified in place and returned).
    basis, predicted : numpy.ndarray, shape (T, 3)
        The basis in force and the new plan's prediction: the new basis keeps the former before ``t0``.
    t0 : int
        The plan's first tick.
    phi0 : numpy.ndarray, shape (L − t0,)
        The weight of the held correction on the samples from ``t0`` on.
    held : numpy.ndarray, shape (3,)
        The held correction the problem assumed.
    emitted : numpy.ndarray, shape (3,), optional
        The velocity emitted at ``t0 − 1``; None if not emitted yet (the plan is then kept as solved).
    anchor : numpy.ndarray, shape (3,)
        The prediction at ``t0 − 1`` (zero for a human at rest), against which ``emitted`` is a correction.
    """
    new_basis = basis.copy()
    new_basis[t0:] = predicted[t0:]
    if emitted is not None:
        plan[t0 : t0 + len(phi0)] += phi0[:, None] * (emitted - anchor - held)
    return plan, new_basis
