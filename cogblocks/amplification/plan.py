"""One decision of :class:`~cogblocks.amplification.OptimalBlender`: its problem's parameters and its outcome.

The altered velocity from tick ``t`` to the planned length ``L`` is the emitted past, then the
predicted human plus a correction ``u`` piecewise linear on knots every ``knot_spacing`` samples
(the first knot, at ``t − 1``, held at the correction applied there). Resampling is linear for a
fixed ``L`` (:func:`~cogblocks.amplification.encoder.resampling_matrix`), so the classifier input,
the cost, the terminal gap and the last speed are all affine or quadratic in the knots: the
matrices :func:`plan_problem` returns. The knot basis and the input map depend only on ``(t, L,
knot_spacing)`` and are cached (:func:`knot_basis`).

Why these decision variables: a correction added to the *measured* human velocity keeps the
terminal constraint independent of the prediction (the final gap is ``dt·Σ u`` whatever the human
does next, once stopped by the planned end); knots every ΔT samples keep the problem small (at most
3 × 19 variables) and the correction smooth; a blend against ``v_r`` would inherit the table's limits.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from cogblocks.amplification.encoder import resampling_matrix
from cogblocks.amplification.encoder_casadi import _U_SCALE
from cogblocks.amplification.kinematics import PlanKinematics
from cogblocks.amplification.subspace import MovementSubspace

__all__ = ["PlanResult", "equivalent_c", "knot_basis", "library_prediction", "plan_problem", "sigmoid", "with_past"]


@dataclass(frozen=True)
class PlanResult:
    """The outcome of one decision of :class:`OptimalBlender`.

    Attributes
    ----------
    tick : int
        The decision's tick (the plan applies from it on).
    end : int
        Planned length ``L`` of the altered movement in force after the decision (0: none).
    eps : float
        ε̂ of the altered movement the block will emit if the human follows the prediction: the
        emitted past, then the plan in force, classified as the online classifier does (restricted
        to its samples faster than ``rest_speed``, resampled).
    distance_mm : float
        ``‖p_a(T) − p_h(T)‖`` at the end of the window under the same assumption.
    solve_ms : float
        Time of the decision (building the problem, solving, checking), in ms of the thread's CPU
        time: the wall time on a dedicated core, not inflated by the slices a shared machine's
        scheduler gives other processes (``benchmarks/optimal_blending.py`` measures both).
    status : str
        ``"converged"``; ``"accepted"`` (stopped by the time limit or the iteration limit, but the
        iterate meets the clipping threshold and δ_pos); ``"fallback"``; ``"ended"`` (the planned
        movement was over: nothing solved).
    ticks : int
        Ticks the decision's work spanned (``solve_ticks`` at most); ``solve_ms`` is their sum.
    """

    tick: int
    end: int
    eps: float
    distance_mm: float
    solve_ms: float
    status: str
    ticks: int = 1


@lru_cache(maxsize=4096)
def knot_basis(t: int, length: int, spacing: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Knots, ``phi0``, ``phi`` and the per-axis input map of a plan from ``t`` to ``length`` (read-only).

    ``phi0`` (samples ``t … L − 1``) weighs the held correction at ``t − 1``, ``phi`` (samples × knots)
    the knot values in units of ``_U_SCALE``; the per-axis input map ``R_L[:, t:] @ phi`` takes the knots
    of one axis to that axis's 20 resampled points.
    """
    knots = np.r_[t - 1, np.arange(t - 1 + spacing, length - 1, spacing), length - 1]
    samples = np.arange(t, length)
    basis = np.stack([np.interp(samples, knots, e) for e in np.eye(len(knots))], axis=1)
    phi0, phi = basis[:, 0], basis[:, 1:] * _U_SCALE
    axis_map = resampling_matrix(length)[:, t:] @ phi
    for array in (knots, phi0, phi, axis_map):
        array.flags.writeable = False
    return knots, phi0, phi, axis_map


def library_prediction(velocity: np.ndarray, human: np.ndarray, t: int, moving: bool = True) -> np.ndarray:
    """The human's prediction at a decision at tick ``t``: η_i's ``velocity`` from ``t − 1`` on, shape (T, 3), zero
    before ``t − 1``; zero throughout unless the human is ``moving`` (then ``t ≥ 1``): a human at rest stays at rest.
    """
    predicted = np.zeros_like(human, dtype=np.float64)
    if moving:
        predicted[t - 1 :] = velocity[t - 1 : len(human)]
    return predicted


def plan_problem(
    t: int,
    length: int,
    predicted: np.ndarray,
    altered: np.ndarray,
    human: np.ndarray,
    reference: np.ndarray,
    knot_spacing: int,
    dt: float,
    rhs: list[float],
    subspace: MovementSubspace | None = None,
    realism: float = 0.0,
    kinematics: bool = False,
) -> dict[str, Any]:
    """The parameters of a plan from tick ``t`` on for a movement of ``length`` samples.

    ``altered`` and ``human`` hold what was emitted and what the human did before ``t``;
    ``predicted`` the human's predicted velocity from ``t`` on (zero before); ``reference`` the
    reference movement's velocity (its direction serves before the human has moved). ``rhs`` is
    ``[sign, z_target, end_speed, delta]``; the returned ``rhs[2]`` is the last knot's required speed
    along the reach direction. With ``subspace``, the cost gains ``realism`` times the squared
    residual of the classifier input (:meth:`MovementSubspace.penalty`). With ``kinematics``, the
    problem holds the plan's kinematic features as ``"kinematics"``
    (:class:`~cogblocks.amplification.kinematics.PlanKinematics` of the movement lasting ``length`` samples).
    """
    knots, phi0, phi, axis_map = knot_basis(t, length, knot_spacing)
    # knots, axis-major: x = x0 + A w, cost wᵀ H w + 2 qᵀ w, gap g0 + C w, last speed dᵀ w
    problem = {
        "A": np.kron(np.eye(3), axis_map),
        "H": np.kron(np.eye(3), phi.T @ phi / _U_SCALE**2),  # the cost Σ‖u‖² in units of _U_SCALE²
        "C": np.kron(np.eye(3), dt * phi.sum(axis=0)),
        "knots": knots[1:],
        "phi": phi,
        "phi0": phi0,
    }
    problem.update(_past_terms(problem, t, length, predicted, altered, human, reference, dt, rhs, kinematics))
    if subspace is not None:  # penalise the altered movement's distance from realistic movements
        h, q = subspace.penalty(problem["A"], problem["x0"])
        problem["H"] = problem["H"] + realism * h / _U_SCALE**2
        problem["q"] = problem["q"] + realism * q / _U_SCALE**2
    return problem


def with_past(
    problem: dict[str, Any],
    t: int,
    length: int,
    predicted: np.ndarray,
    altered: np.ndarray,
    human: np.ndarray,
    reference: np.ndarray,
    dt: float,
    rhs: list[float],
    subspace: MovementSubspace | None = None,
    realism: float = 0.0,
) -> dict[str, Any]:
    """``problem`` (a :func:`plan_problem` from ``t`` for ``length`` samples) for another past, as a new dict.

    The knots act from ``t`` on, so a new past (``altered`` and ``human`` before ``t``) changes only the
    problem's fixed part: ``x0``, ``q``, ``g0``, ``d``, ``rhs``, ``u_prev`` and the kinematics' base; ``A``,
    ``H``, ``C`` and the basis are shared with ``problem``. The arguments are :func:`plan_problem`'s (the
    same ``predicted``, ``reference``, ``rhs``, ``subspace`` and ``realism`` give the same problem).
    """
    new = dict(problem)
    kinematics = "kinematics" in problem
    new.update(_past_terms(problem, t, length, predicted, altered, human, reference, dt, rhs, kinematics))
    if subspace is not None:  # the penalty's quadratic part depends on A only
        _, q = subspace.penalty(problem["A"], new["x0"])
        new["q"] = new["q"] + realism * q / _U_SCALE**2
    return new


def _past_terms(
    problem: dict[str, Any], t: int, length: int, predicted: np.ndarray, altered: np.ndarray, human: np.ndarray,
    reference: np.ndarray, dt: float, rhs: list[float], kinematics: bool,
) -> dict[str, Any]:  # fmt: skip
    """The entries of a plan's problem that depend on the past before ``t`` (``q`` without the realism penalty)."""
    sign, z_target, end_speed, delta = rhs
    phi, phi0 = problem["phi"], problem["phi0"]
    u_prev = altered[t - 1] - human[t - 1] if t > 0 else np.zeros(3)
    base = np.concatenate([altered[:t], predicted[t:length] + phi0[:, None] * u_prev])
    reach = human[:t].sum(axis=0)
    if not np.linalg.norm(reach) > 0.0:
        reach = reference.sum(axis=0)
    direction = reach / max(np.linalg.norm(reach), 1e-12)
    speed = np.zeros((3, phi.shape[1]))
    speed[:, -1] = _U_SCALE * direction  # the last knot's speed along the reach direction
    terms = {
        "x0": (resampling_matrix(length) @ base).T.reshape(-1),
        "q": ((phi.T @ phi0)[None, :] * u_prev[:, None] / _U_SCALE**2).ravel(),
        "g0": dt * ((altered[:t] - human[:t]).sum(axis=0) + phi0.sum() * u_prev - predicted[length:].sum(axis=0)),
        "d": speed.ravel(),
        "rhs": [sign, z_target, end_speed - direction @ predicted[length - 1], delta],
        "u_prev": u_prev,
    }
    if kinematics:
        terms["kinematics"] = PlanKinematics(base, t, phi, dt)
    return terms


def sigmoid(z: float) -> float:
    """The logistic function without overflow for large ``|z|``."""
    e = math.exp(-abs(z))
    return 1.0 / (1.0 + e) if z >= 0 else e / (1.0 + e)


def equivalent_c(v_a: np.ndarray, v_h: np.ndarray, v_r: np.ndarray) -> float:
    """The ``c`` whose blend ``c·v_h + (1 − c)·v_r`` is closest to ``v_a``, clipped to [0, 1] (1 if undefined)."""
    if not (np.all(np.isfinite(v_a)) and np.all(np.isfinite(v_h)) and np.all(np.isfinite(v_r))):
        return 1.0
    span = v_h - v_r
    scale = float(np.abs(span).max())
    if not scale > 1e-6:
        return 1.0
    span = span / scale  # no overflow for huge (finite) inputs
    return min(max(float(((v_a - v_r) / scale) @ span) / float(span @ span), 0.0), 1.0)
