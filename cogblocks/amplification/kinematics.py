"""The kinematic features of a planned movement and their (sub)gradient with respect to the plan's knots.

Networks of the ``mlp_kinematic`` architecture take, after the 60 resampled points, the six
:func:`~cogblocks.amplification.judges.kinematic_features` of the movement. For a plan of fixed length
``L`` the velocity is affine in the knots ``w`` (:func:`~cogblocks.amplification.plan.plan_problem`:
the emitted past, then the prediction plus ``Φ w`` per axis), so each feature is a simple function of
``w``: the peak speed a maximum of norms (its subgradient: the arg-max sample's), the mean speed and
the log mean jerk sums of norms (differentiable wherever no norm is zero; a zero norm contributes no
gradient), and the time to peak, the duration and the peak's share of the duration piecewise constant
(zero gradient: a jump of the arg-max is left to the solver's line search on the exact merit).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["PlanKinematics", "plan_features"]


#: Rows of the features with a nonzero gradient: peak speed, log mean jerk, mean speed.
_SMOOTH_ROWS = (0, 3, 4)


def _norms(v: np.ndarray) -> np.ndarray:
    """The Euclidean norm of each row of ``v`` (n, 3), summed as ``np.linalg.norm(v, axis=1)`` sums."""
    square = v * v
    return np.sqrt(square[:, 0] + square[:, 1] + square[:, 2])


def plan_features(velocity: np.ndarray, dt: float, gradient: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
    """:func:`~cogblocks.amplification.judges.kinematic_features` of ``velocity`` (L, 3) taken as lasting L samples,
    and the gradients of the rows :data:`_SMOOTH_ROWS` in the samples, shape (3, L, 3) (None unless ``gradient``);
    the others have none.

    The judges restrict a movement to its last sample faster than the rest speed; a plan fixes that
    length (its last sample keeps moving), so here the whole of ``velocity`` is the movement. The values are
    the same floating-point numbers with or without ``gradient`` (the line search takes them without).
    """
    v = np.asarray(velocity, dtype=np.float64)
    length = len(v)
    # the norms, means and differences of np.linalg.norm, np.mean and np.diff, the same sums in the same order,
    # without their generic overhead (a few µs a call, as much as the arithmetic on these small arrays)
    speed = _norms(v)
    peak = int(speed.argmax())
    if length > 2:
        step = v[1:] - v[:-1]
        jerk = (step[1:] - step[:-1]) / dt**2
        size = _norms(jerk)
        mean_jerk = float(np.add.reduce(size) / len(size))
    else:
        mean_jerk = 0.0
    mean_speed = float(np.add.reduce(speed) / length)
    values = np.array([speed[peak], peak * dt, length * dt, math.log1p(mean_jerk), mean_speed, peak / length])
    if not gradient:
        return values, None
    grads = np.zeros((3, length, 3))
    grads[0, peak] = v[peak] / speed[peak] if speed[peak] > 0.0 else 0.0
    np.divide(v, length * speed[:, None], out=grads[2], where=speed[:, None] > 0.0)
    if length > 2:
        # d log1p(mean ‖j‖) / dv: the second difference's transpose of the unit jerks
        unit = np.divide(jerk, size[:, None], out=np.zeros_like(jerk), where=size[:, None] > 0.0)
        unit /= dt**2 * len(size) * (1.0 + mean_jerk)
        grads[1, :-2] += unit
        grads[1, 1:-1] -= 2.0 * unit
        grads[1, 2:] += unit
    return values, grads


class PlanKinematics:
    """The kinematic features of ``v(w) = base + [0; Φ w]`` (per axis) and their Jacobian in ``w``.

    Parameters
    ----------
    base : numpy.ndarray, shape (L, 3)
        The velocity without the knots' contribution (mm/s): the emitted past and the prediction.
    t : int
        First sample the knots move (``base[:t]`` is fixed).
    phi : numpy.ndarray, shape (L − t, n)
        Each knot's weight on the samples ``t … L − 1`` (one axis); ``w`` is axis-major, shape (3·n,).
    dt : float
        Sampling step in seconds.
    """

    def __init__(self, base: np.ndarray, t: int, phi: np.ndarray, dt: float) -> None:
        self.base = np.asarray(base, dtype=np.float64)
        self.t, self.phi, self.dt = int(t), np.asarray(phi, dtype=np.float64), float(dt)

    def velocity(self, w: np.ndarray) -> np.ndarray:
        """``v(w)``, shape (L, 3)."""
        v = self.base.copy()
        v[self.t :] += self.phi @ np.reshape(w, (3, -1)).T
        return v

    def __call__(self, w: np.ndarray, jacobian: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """The six features at ``w`` (order of :data:`~cogblocks.amplification.judges.FEATURES`) and their
        Jacobian, shape (6, 3·n), a subgradient at a kink (see the module docstring); None unless ``jacobian``."""
        values, grads = plan_features(self.velocity(w), self.dt, gradient=jacobian)
        if grads is None:
            return values, None
        out = np.zeros((6, self.phi.shape[1] * 3))
        # the gradient in v restricted to the moving samples, through Φ per axis (axis-major like w)
        out[list(_SMOOTH_ROWS)] = (grads[:, self.t :].transpose(0, 2, 1) @ self.phi).reshape(3, -1)
        return values, out
