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
    mm = m.tolist()  # pure Python below: for so few variables NumPy's call overhead dominates
    ridge = 1e-12 * max(sum(row[i] for i, row in enumerate(mm)), 1e-300)  # a semidefinite M: nearly least-norm
    for i, row in enumerate(mm):
        row[i] += ridge
    bb, ub = b.tolist(), [float(v) for v in upper]
    if start is None:
        lam, held = [0.0] * r, [True] * r
    else:
        lam = [min(max(float(v), 0.0), u) for v, u in zip(start, ub, strict=True)]
        held = [v <= 0.0 or v >= u for v, u in zip(lam, ub, strict=True)]
    tol = 1e-10 * (1.0 + max(abs(v) for v in bb))
    for _ in range(8 * r + 8):
        free = [i for i, h in enumerate(held) if not h]
        # the held variables stay where they are: only the free ones move (their step, zero for the others)
        direction = []
        if free:
            fixed = [v if h else 0.0 for v, h in zip(lam, held, strict=True)]  # the free ones' terms add zeros
            rhs = [bb[i] - sum(map(mul, mm[i], fixed)) for i in free]
            target = _solve([[mm[i][j] for j in free] for i in free], rhs)
            direction = [t - lam[i] for t, i in zip(target, free, strict=True)]
        if not free or max(map(abs, direction)) <= tol * (1.0 + max(map(abs, lam))):
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
        step, block, bound = 1.0, -1, 0.0
        for i, d in zip(free, direction, strict=True):
            limit = -lam[i] / d if d < 0 else (ub[i] - lam[i]) / d if d > 0 else math.inf
            if limit < step:
                step, block, bound = limit, i, 0.0 if d < 0 else ub[i]
        for i, d in zip(free, direction, strict=True):
            lam[i] = min(max(lam[i] + step * d, 0.0), ub[i])
        if block >= 0:
            # exactly at its bound: a rounding residue (say 1e-256 above zero) would pass for the other bound
            lam[block], held[block] = bound, True
    return np.array(lam)


def _solve(a: list[list[float]], y: list[float]) -> list[float]:
    """``a x = y`` for a small symmetric positive definite ``a`` (box_qp's free block: 1–5 variables), by ``LDLᵀ``.

    No pivoting is needed for a positive definite matrix, and no square root (none to fail on a pivot that
    rounding leaves at or below zero): about half the products of Gaussian elimination, in plain loops.
    """
    if len(y) == 1:  # the most frequent sizes, in closed form (Cramer's rule for two)
        return [y[0] / a[0][0]]
    if len(y) == 2:
        (p, q), (_, s) = a
        det = p * s - q * q
        return [(s * y[0] - q * y[1]) / det, (p * y[1] - q * y[0]) / det]
    low: list[list[float]] = []  # the unit lower factor's rows, each without its diagonal
    diag: list[float] = []
    for i, row in enumerate(a):
        scaled: list[float] = []  # row i of L D, built left to right
        for j in range(i):
            scaled.append(row[j] - sum(map(mul, scaled, low[j])))
        factor = [v / d for v, d in zip(scaled, diag, strict=True)]
        low.append(factor)
        diag.append(row[i] - sum(map(mul, scaled, factor)))
    z: list[float] = []
    for i, factor in enumerate(low):
        z.append(y[i] - sum(map(mul, factor, z)))
    n = len(y)
    x = [0.0] * n
    for i in reversed(range(n)):
        x[i] = z[i] / diag[i] - sum(low[k][i] * x[k] for k in range(i + 1, n))
    return x
