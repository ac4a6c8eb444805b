"""A fast solver of the optimised blender's decision: sequential QPs on the exact ReLU networks.

The encoder networks are piecewise linear in their inputs (ReLU): around a plan each network's
logit is exactly affine until a hidden unit changes sign, and there is no curvature to compute.
:class:`LinearisedSolver` linearises every network at the current plan (one product with the
stacked first layer) and solves the QP of the convex cost with the linearised encoding constraints
through its dual, a box-constrained QP in one variable per constraint (:func:`box_qp`); the
terminal ball enters as tangent half-spaces added while the step lies outside it (cutting planes).
A backtracking line search on the exact ℓ1 merit keeps the steps where the linearisation holds.
casadi's SQP spends most of its time on the Hessian of the smoothed networks; this solver needs
none and runs in NumPy.
"""

from __future__ import annotations

import math
import time
from contextlib import AbstractContextManager
from functools import cache
from typing import Any

import numpy as np
from scipy.linalg import cho_factor
from scipy.linalg.lapack import dpotrs
from threadpoolctl import ThreadpoolController

from cogblocks.amplification.boxqp import box_qp
from cogblocks.sim.params import flag, one_of

__all__ = ["GRADIENTS", "LinearisedRun", "LinearisedSolver", "box_qp", "network_input", "one_blas_thread"]

#: How :class:`LinearisedSolver` takes the members' gradients (its ``gradient``).
GRADIENTS = ("stacked", "blocks")

_PENALTY = 1e3  # as the SQP's: weight of the encoding slack per logit unit


@cache
def _blas() -> ThreadpoolController:
    """The BLAS libraries loaded (NumPy's and SciPy's OpenBLAS), found once: looking them up takes milliseconds."""
    return ThreadpoolController().select(user_api="blas")


def one_blas_thread() -> AbstractContextManager:
    """A context in which BLAS runs on the calling thread only (about 20 µs to enter and leave).

    With several members the stacked first layer (e.g. 2200 × 66 for eleven networks) is large enough for
    OpenBLAS to split its products over threads; on a machine whose other cores are busy the calling thread
    then waits, spinning, for a thread that is not scheduled, and a tick's CPU time grows tenfold
    (docs/validation/amplification.md). One thread is fast enough at these sizes.
    """
    return _blas().limit(limits=1)


def network_input(p: dict[str, Any], w: np.ndarray, jacobian: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
    """The networks' input at plan variables ``w`` and its Jacobian in ``w`` (None unless ``jacobian``).

    ``x0 + A w`` (Jacobian ``A`` itself); with ``p["kinematics"]``
    (:class:`~cogblocks.amplification.kinematics.PlanKinematics`), followed by the plan's exact kinematic
    features, whose (sub)gradient rows follow ``A``'s: the solver re-linearises at every iteration, so a
    Jacobian exact only near ``w`` is all it needs. The input is the same with or without ``jacobian``.
    """
    profile = p["x0"] + p["A"] @ w
    kinematics = p.get("kinematics")
    if kinematics is None:
        return profile, p["A"] if jacobian else None
    features, rows = kinematics(w, jacobian=jacobian)
    x = np.concatenate([profile, features])
    return x, np.concatenate([p["A"], rows]) if jacobian else None


class LinearisedSolver:
    """Sequential QPs with linearised ReLU networks (see the module docstring).

    Parameters
    ----------
    w1, b1 : numpy.ndarray
        The members' first layers stacked, input normalisation folded in: (members·hidden, inputs); the
        inputs are the 60 profile points, or those and the six kinematic features (:func:`network_input`).
    w2, b2 : sequence of numpy.ndarray, numpy.ndarray
        Each member's output weights (hidden,) and biases (members,).
    sign : float
        +1 for ``e_des = 1`` (logits must be high), −1 for ``e_des = 0``.
    proximal : float
        Weight of ``‖w − w_k‖²`` added to each QP relative to the cost's mean curvature: keeps a step
        near the region where the linearisation is exact.
    gradient : {"blocks", "stacked"}
        How the members' gradients are taken: each member's from its own block of the stacked first layer (one
        batched product), or one product of the block-diagonal output weights with the whole stacked layer, which
        multiplies the other members' zeros (the same values to rounding, several times the time for seven members;
        kept as the straightforward reference the tests compare with).
    predict_setup : bool
        Whether the prediction of the next iteration's CPU time (:meth:`LinearisedRun.run`) counts the solve's
        preparation (the factorisation and the first linearisation) that the first iteration of a run carries.
    """

    def __init__(self, w1: np.ndarray, b1: np.ndarray, w2: list[np.ndarray], b2: np.ndarray, sign: float,
                 proximal: float = 0.1, gradient: str = "blocks", predict_setup: bool = True) -> None:  # fmt: skip
        self.w1, self.b1, self.sign, self.proximal = w1, b1, sign, proximal
        self.gradient = one_of(self, "gradient", gradient, GRADIENTS)
        self.predict_setup = flag(self, "predict_setup", predict_setup)
        self.w2 = np.zeros((len(w2), len(b1)))
        ends = np.cumsum([len(w) for w in w2])
        blocks = [slice(end - len(w), end) for end, w in zip(ends, w2, strict=True)]  # each member's hidden units
        for k, (rows, w) in enumerate(zip(blocks, w2, strict=True)):
            self.w2[k, rows] = w
        # each member's own block of the first layer, padded with zero rows to the largest (a batched product);
        # _gather picks each member's output weights times its units' activity, the padding's from a trailing zero
        hidden = max(len(w) for w in w2)
        self._gather = np.full((len(w2), hidden), len(b1))
        for k, rows in enumerate(blocks):
            self._gather[k, : rows.stop - rows.start] = np.arange(rows.start, rows.stop)
        if hidden * len(w2) == len(b1):  # no padding: a view of the stacked layer, not a second copy in the cache
            self._own = w1.reshape(len(w2), hidden, w1.shape[1])  # (an iteration 0.92x as long on the shipped seven)
        else:
            self._own = np.zeros((len(w2), hidden, w1.shape[1]))
            for k, rows in enumerate(blocks):
                self._own[k, : rows.stop - rows.start] = w1[rows]
        self._weights = np.append(self.w2.sum(axis=0), 0.0)  # the output weight of every hidden unit (one member's)
        self.b2 = np.asarray(b2, dtype=np.float64)
        self.iteration = 0.0  # CPU seconds of the last iteration: the prediction of the next one's

    def logits(self, x: np.ndarray, gradient: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """Every member's logit at input ``x`` and its gradient (members, inputs; None unless ``gradient``)."""
        logits, active = self._forward(x)
        return logits, self._gradients(active) if gradient else None

    def _forward(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Every member's logit at input ``x`` and which hidden units are active there (all the gradient needs)."""
        pre = self.w1 @ x + self.b1
        active = pre > 0.0
        return self.w2 @ np.where(active, pre, 0.0) + self.b2, active

    def _gradients(self, active: np.ndarray) -> np.ndarray:
        """The members' gradients in the input with the hidden units ``active`` (see ``gradient``)."""
        if self.gradient == "stacked":
            return (self.w2 * active) @ self.w1
        # "blocks": member k's gradient from its own rows only; the stacked product multiplies the others' zeros
        weighted = self._weights * np.append(active, False)
        return np.matmul(weighted[self._gather][:, None, :], self._own)[:, 0]

    def _merit(
        self, p: dict[str, Any], w: np.ndarray, z_target: float, delta: float
    ) -> tuple[float, np.ndarray, np.ndarray]:
        """The exact ℓ1 merit of ``w``: cost plus ρ per logit unit short of ``z_target`` and per mm beyond ``delta``.

        Also returns the members' logits at ``w`` and their active hidden units (:meth:`_forward`), from which
        :meth:`_linearise` takes the gradients if ``w`` is kept: the line search rejects most trial points.
        """
        x, _ = network_input(p, w, jacobian=False)
        z, active = self._forward(x)
        gap = p["g0"] + p["C"] @ w
        excess = max(math.sqrt(float(gap @ gap)) - delta, 0.0)
        cost = float(w @ p["H"] @ w + 2.0 * p["q"] @ w)
        short = float(np.maximum(z_target - self.sign * z, 0.0).sum())
        return cost + _PENALTY * (short + excess), z, active

    def _linearise(self, p: dict[str, Any], w: np.ndarray, z: np.ndarray, active: np.ndarray) -> tuple:
        """The linearisation at ``w`` for the next iteration: the logits ``z``, their gradients in the networks'
        input (from the ``active`` units of :meth:`_merit`) and that input's Jacobian in ``w``."""
        return z, self._gradients(active), network_input(p, w)[1]

    def _line_search(
        self, p: dict[str, Any], w: np.ndarray, step: np.ndarray, merit: float, z_target: float, delta: float
    ) -> tuple[np.ndarray, tuple, float, float]:
        """The first ``w + α (step − w)``, α = 1, ½, ¼, ⅛, below ``merit`` (else the lowest).

        Returns the point, its linearisation (:meth:`_linearise`), the largest change of a variable, and its merit.
        """
        direction, best = step - w, None
        for alpha in (1.0, 0.5, 0.25, 0.125):
            trial = w + alpha * direction
            value, z, active = self._merit(p, trial, z_target, delta)
            if best is None or value < best[3]:
                best = (trial, (z, active), alpha, value)
            if value < merit:
                break
        trial, (z, active), alpha, value = best
        return trial, self._linearise(p, trial, z, active), alpha * float(np.abs(direction).max()), value

    @staticmethod
    def _qp_step(
        rows: np.ndarray, h: np.ndarray, hq: np.ndarray, hg: np.ndarray, upper: np.ndarray, members: int,
        start: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
        """The QP's minimiser ``H⁻¹(Gᵀλ/2 − q)`` from its dual, and the multipliers λ.

        :func:`box_qp` starts from ``start`` (the last QP's multipliers, zero for rows it did not have): the same
        minimiser, in fewer active-set steps. Unless one of them was active there, the rows after the members' are
        tried inactive first (a smaller dual, often enough).
        """
        dual, linear = 0.5 * rows @ hg, rows @ hq + h
        if not np.any(start[members:] > 0.0):
            lam = np.zeros(len(h))
            lam[:members] = box_qp(dual[:members, :members], linear[:members], upper[:members], start[:members])
            step = hg @ lam / 2.0 - hq
            if not np.any(rows[members:] @ step < h[members:] - 1e-9):
                return step, lam
            start = np.concatenate([lam[:members], start[members:]])
        lam = box_qp(dual, linear, upper, start)
        return hg @ lam / 2.0 - hq, lam

    def solve(
        self,
        p: dict[str, Any],
        w0: np.ndarray,
        z_target: float,
        z_clip: float,
        delta: float,
        delta_pos: float,
        time_limit: float,
        max_iter: int = 10,
    ) -> tuple[np.ndarray | None, str, int]:
        """Plan variables (None: none acceptable), status and iterations of one decision, in one go.

        :meth:`start` followed by one :meth:`LinearisedRun.run` with ``time_limit`` seconds of CPU time
        from now, at least one iteration (see :class:`LinearisedRun` for the iterations and statuses).
        """
        deadline = time.thread_time() + time_limit
        run = self.start(p, w0, z_target, z_clip, delta, delta_pos, max_iter)
        run.run(deadline, at_least_one=True)
        return run.result()

    def start(
        self,
        p: dict[str, Any],
        w0: np.ndarray,
        z_target: float,
        z_clip: float,
        delta: float,
        delta_pos: float,
        max_iter: int = 10,
    ) -> LinearisedRun:
        """A resumable solve of one decision from ``w0`` (:class:`LinearisedRun`); nothing is iterated yet."""
        return LinearisedRun(self, p, w0, z_target, z_clip, delta, delta_pos, max_iter)


class LinearisedRun:
    """One decision's solve by :class:`LinearisedSolver`, resumable over several calls of :meth:`run`.

    ``p`` holds ``A, x0, H, q, C, g0, d`` and ``rhs`` as the SQP's parameters (classifier input
    ``x0 + A w``, followed by the plan's kinematic features if ``p`` has ``kinematics``, cost
    ``wᵀHw + 2qᵀw``, gap ``g0 + C w``, last speed ``dᵀw ≥ rhs[2]``). Each
    iteration solves ``min wᵀHw + 2qᵀw + μ‖w − w_k‖² + ρ Σ s_j`` subject to the members'
    linearised encoding constraints ``sign·z_j ≥ z_target`` (slack ``s_j`` each) and the speed
    constraint, through its dual (:func:`box_qp`), adding up to two tangent planes of the ball
    ``‖gap‖ ≤ delta`` while the step lies outside it; then a backtracking line search on the
    exact ℓ1 merit. An iterate is acceptable when every exact network is beyond ``z_clip`` and
    the gap within ``delta_pos``; the cheapest acceptable iterate is kept, ``"converged"`` once a
    step is small (or no cheaper) and meets ``z_target``, otherwise ``"accepted"``; a fixed point
    short of ``z_clip`` within ``delta_pos`` is kept as ``"converged"`` too (as close as the plan can
    get, like the SQP's exact penalty). Without an acceptable iterate the status is ``"fallback"``.
    """

    def __init__(self, solver: LinearisedSolver, p: dict[str, Any], w0: np.ndarray, z_target: float,
                 z_clip: float, delta: float, delta_pos: float, max_iter: int) -> None:  # fmt: skip
        self.solver, self.p = solver, p
        self.z_target, self.z_clip, self.delta, self.delta_pos, self.max_iter = (
            z_target, z_clip, delta, delta_pos, max_iter
        )  # fmt: skip
        self.w = np.asarray(w0, dtype=np.float64)
        self.members = len(solver.b2)
        self.best, self.best_cost, self.status, self.done = None, np.inf, "fallback", 0
        self._factor = None

    @property
    def finished(self) -> bool:
        """Converged or out of iterations: further :meth:`run` calls do nothing."""
        return self.status == "converged" or self.done >= self.max_iter

    def result(self) -> tuple[np.ndarray | None, str, int]:
        """The kept plan variables (None: none acceptable), the status and the iterations run so far."""
        return self.best, self.status, self.done

    def update(self, p: dict[str, Any]) -> None:
        """Continue from the current iterate on ``p``, the problem with a new fixed part (the same ``A``, ``H``, ``C``).

        The merit and the linearisation are taken at the current iterate on ``p``; the kept iterate stays
        only if it is acceptable on ``p`` too (with its cost on ``p``), and a converged run resumes, so that
        the result is judged on the problem it will be used for.
        """
        self.p = p
        if self._factor is not None:  # H is unchanged: the factor stays
            self.merit, self._linear = self._linearised_merit(self.w)
        if self.best is None:
            return
        x, _ = network_input(p, self.best, jacobian=False)
        reached, cost, within = self._assess(self.best, self.solver._forward(x)[0])
        if reached > self.z_clip and within:
            self.best_cost, self.status = cost, "accepted"
        else:
            self.best, self.best_cost, self.status = None, np.inf, "fallback"

    def _assess(self, w: np.ndarray, z: np.ndarray) -> tuple[float, float, bool]:
        """The least favourable member's ``sign·z``, the cost and whether the gap is within ``delta_pos``, at ``w``."""
        p = self.p
        reached = float((self.solver.sign * z).min())
        cost = float(w @ p["H"] @ w + 2.0 * p["q"] @ w)
        gap = p["g0"] + p["C"] @ w
        return reached, cost, math.sqrt(float(gap @ gap)) <= self.delta_pos

    def _linearised_merit(self, w: np.ndarray) -> tuple[float, tuple]:
        """The merit at ``w`` and the linearisation there (:meth:`LinearisedSolver._linearise`)."""
        merit, z, active = self.solver._merit(self.p, w, self.z_target, self.delta)
        return merit, self.solver._linearise(self.p, w, z, active)

    def _solve_h(self, b: np.ndarray) -> np.ndarray:
        """``(H + μI)⁻¹ b`` from the factor: LAPACK's ``potrs`` as ``cho_solve`` calls it, without its checks."""
        factor, lower = self._factor
        x, _ = dpotrs(factor, b, lower=lower)
        return x

    def _prepare(self) -> None:
        p, m, rows = self.p, len(self.w), self.members + 3  # the members', the speed's, two tangent planes
        self.mu = self.solver.proximal * max(np.trace(p["H"]) / m, 1e-12)
        self._factor = cho_factor(p["H"] + self.mu * np.eye(m))
        # the QP's rows G w ≥ h and H_μ⁻¹ Gᵀ, filled in place each iteration
        self._rows, self._h, self._hg = np.empty((rows, m)), np.empty(rows), np.empty((m, rows), order="F")
        self._upper = np.r_[np.full(self.members, _PENALTY), np.full(3, np.inf)]
        self._lam = np.zeros(self.members + 1)  # the last QP's multipliers of the members' and the speed's rows
        self.merit, self._linear = self._linearised_merit(self.w)

    def run(self, deadline: float, *, at_least_one: bool = False, clock: Any = time.thread_time) -> bool:
        """Iterate until finished or until the next iteration is predicted to end past ``deadline``.

        ``deadline`` is a value of ``clock`` (the thread's CPU time in seconds by default); an
        iteration is predicted to take as long as the solver's last one (:attr:`LinearisedSolver.iteration`; the
        first iteration's without the preparation unless ``predict_setup``), so none starts that would end past it,
        unless ``at_least_one`` and none has run in this call.
        Returns :attr:`finished`.
        """
        solver, p, members = self.solver, self.p, self.members
        c, g0, delta = p["C"], p["g0"], self.delta
        ran = 0
        while not self.finished:
            now = clock()
            if now + solver.iteration > deadline and not (at_least_one and ran == 0):
                break
            if self._factor is None:
                self._prepare()
                if not solver.predict_setup:  # the next iteration will not carry the preparation
                    now = clock()
            z, g, jacobian = self._linear
            w, r, rows, h, hg, upper = self.w, members + 1, self._rows, self._h, self._hg, self._upper
            # rows G w ≥ h: encoding (linearised at w), speed; then tangents of the terminal ball as needed
            rows[:members] = solver.sign * (g @ jacobian)
            rows[members] = p["d"]
            h[:members] = self.z_target - solver.sign * z + rows[:members] @ w
            h[members] = p["rhs"][2]
            hq = self._solve_h(p["q"] - self.mu * w)
            hg[:, :r] = self._solve_h(rows[:r].T)
            step, lam = solver._qp_step(rows[:r], h[:r], hq, hg[:, :r], upper[:r], members, self._lam)
            for _ in range(2):  # cutting planes: a tangent of the ball at the new gap while it lies outside
                outside = g0 + c @ step
                distance = math.sqrt(float(outside @ outside))
                if distance <= delta * 1.001:
                    break
                normal = outside / distance
                rows[r], h[r], hg[:, r] = -normal @ c, normal @ g0 - delta, self._solve_h(-c.T @ normal)
                r += 1
                step, lam = solver._qp_step(rows[:r], h[:r], hq, hg[:, :r], upper[:r], members, np.append(lam, 0.0))
            self._lam = lam[: members + 1]
            w, self._linear, moved, self.merit = solver._line_search(p, w, step, self.merit, self.z_target, delta)
            self.w = w
            self.done += 1
            ran += 1
            reached, cost, within = self._assess(w, self._linear[0])
            if reached > self.z_clip and within and cost < self.best_cost:
                improved = cost < self.best_cost - 1e-3 * abs(self.best_cost)
                self.best, self.best_cost = w.copy(), cost
                # a small step, or no better plan any more, meeting the planned target: stop here
                converged = reached >= self.z_target - 1e-6 and (moved < 1e-2 or not improved)
                self.status = "converged" if converged else "accepted"
            if self.best is None and within and moved < 1e-2:
                self.best, self.status = w.copy(), "converged"  # a fixed point short of the threshold
            solver.iteration = clock() - now  # the next iteration is predicted to take as long as this one
        return self.finished
