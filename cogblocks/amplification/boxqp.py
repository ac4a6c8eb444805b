"""The dual of the linearised solver's QPs: a small box-constrained QP, solved exactly by a primal active-set method.

One variable per constraint of :class:`~cogblocks.amplification.linearised.LinearisedSolver`'s QP (the members'
encoding rows, the speed's, up to two tangent planes): 7–10 variables, so pure Python is faster than NumPy's call
overhead, and the previous QP's multipliers make a start a step or two from the minimiser.
"""

from __future__ import annotations

import math
from operator import mul

import numpy as np

__all__ = ["box_qp"]


def box_qp(m: np.ndarray, b: np.ndarray, upper: np.ndarray, start: np.ndarray | None = None) -> np.ndarray:
    """The minimiser of ``½ λᵀ M λ − bᵀ λ`` over ``0 ≤ λ ≤ upper`` (M symmetric positive semidefinite, few variables).

    A primal active-set method on the bounds: from ``λ = 0`` (or ``start`` clipped to the bounds, its
    variables at a bound held there), solve for the free variables with the others at their bounds; step to
    that point or to the first bound in the way (which then holds), and free the bound variable whose gradient
    most wants to leave its bound, until none does. Exact in finitely many steps; from a ``start`` near the
    minimiser (the previous QP's multipliers) a step or two instead of one per variable that is not at zero.
    ``upper`` may hold ``inf``. The ridge makes the minimiser unique, so the start changes only the rounding.
    """
    r = len(b)
    ridge = 1e-12 * max(float(np.trace(m)), 1e-300)  # a semidefinite M: a nearly least-norm minimiser
    mm = (m + ridge * np.eye(r)).tolist()  # pure Python below: for so few variables NumPy's call overhead dominates
    bb, ub = b.tolist(), [float(v) for v in upper]
    if start is None:
        lam, held = [0.0] * r, [True] * r
    else:
        lam = [min(max(float(v), 0.0), u) for v, u in zip(start, ub, strict=True)]
        held = [v <= 0.0 or v >= u for v, u in zip(lam, ub, strict=True)]
    tol = 1e-10 * (1.0 + max(abs(v) for v in bb))
    for _ in range(8 * r + 8):
        free = [i for i in range(r) if not held[i]]
        target = lam[:]
        if free:
            fixed = [v if h else 0.0 for v, h in zip(lam, held, strict=True)]  # the free ones' terms add zeros
            rhs = [bb[i] - sum(map(mul, mm[i], fixed)) for i in free]
            for i, v in zip(free, _solve([[mm[i][j] for j in free] for i in free], rhs), strict=True):
                target[i] = v
        direction = [t - v for t, v in zip(target, lam, strict=True)]
        if max(map(abs, direction)) <= tol * (1.0 + max(map(abs, lam))):
            best, leave = tol, -1
            for i in range(r):
                if held[i]:
                    grad = sum(map(mul, mm[i], lam)) - bb[i]
                    want = -grad if lam[i] <= 0.0 else grad  # > 0: leaving its bound lowers the objective
                    if want > best:
                        best, leave = want, i
            if leave < 0:
                break
            held[leave] = False
            continue
        step, block = 1.0, -1
        for i in free:
            d = direction[i]
            limit = -lam[i] / d if d < 0 else (ub[i] - lam[i]) / d if d > 0 else math.inf
            if limit < step:
                step, block = limit, i
        lam = [min(max(v + step * d, 0.0), u) for v, d, u in zip(lam, direction, ub, strict=True)]
        if block >= 0:
            held[block] = True
    return np.array(lam)


def _solve(a: list[list[float]], y: list[float]) -> list[float]:
    """``a x = y`` for a small dense system, Gaussian elimination with partial pivoting (in place)."""
    n = len(y)
    for k in range(n):
        pivot = max(range(k, n), key=lambda i: abs(a[i][k]))
        a[k], a[pivot], y[k], y[pivot] = a[pivot], a[k], y[pivot], y[k]
        for i in range(k + 1, n):
            f = a[i][k] / a[k][k]
            for j in range(k, n):
                a[i][j] -= f * a[k][j]
            y[i] -= f * y[k]
    x = [0.0] * n
    for k in reversed(range(n)):
        x[k] = (y[k] - sum(a[k][j] * x[j] for j in range(k + 1, n))) / a[k][k]
    return x
