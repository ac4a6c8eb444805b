"""Classifier inputs of the PoP of Amplification: each movement resampled to a fixed number of points.

The encoding classifier of the appendix paper (section V-B) sees a velocity signal restricted to the
movement's own duration and resampled to 20 points per axis by cubic interpolation: 60 inputs.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from scipy.interpolate import CubicSpline

if TYPE_CHECKING:
    from cogblocks.data.reach import ReachLibrary

__all__ = ["classifier_inputs", "resample_movement"]


def resample_movement(velocity: np.ndarray, length: int, n_points: int = 20) -> np.ndarray:
    """Restrict a velocity signal to its first ``length`` samples and resample each axis.

    The movement's samples are placed on a uniform grid of [0, 1] and interpolated at ``n_points``
    uniform points of the same interval, so that the first and last samples are kept exactly.
    Interpolation is a not-a-knot cubic spline (``scipy.interpolate.CubicSpline``, the same curve as
    ``interp1d(kind="cubic")``). A cubic needs at least 4 samples: with 2 or 3 samples the
    interpolation is linear, and a single sample is repeated.

    Parameters
    ----------
    velocity : numpy.ndarray, shape (max_len, n_axes)
        Padded velocity signal of one movement.
    length : int
        Number of samples of the movement, in ``1 .. max_len``.
    n_points : int
        Number of resampled points per axis (at least 1).

    Returns
    -------
    numpy.ndarray, shape (n_axes * n_points,)
        Axis-major: all points of x, then of y, then of z.
    """
    signal = np.asarray(velocity, dtype=np.float64)
    if signal.ndim != 2:
        raise ValueError(f"velocity must have shape (max_len, n_axes), got {signal.shape}")
    if isinstance(length, bool) or not isinstance(length, (int, np.integer)) or not 1 <= length <= signal.shape[0]:
        raise ValueError(f"length must be an integer in 1..{signal.shape[0]}, got {length!r}")
    if isinstance(n_points, bool) or not isinstance(n_points, (int, np.integer)) or n_points < 1:
        raise ValueError(f"n_points must be an integer >= 1, got {n_points!r}")
    samples = signal[:length]
    if length == 1:
        return np.repeat(samples, n_points, axis=0).T.reshape(-1)
    old_grid = np.linspace(0.0, 1.0, length)
    new_grid = np.linspace(0.0, 1.0, n_points)
    if length < 4:
        resampled = np.column_stack([np.interp(new_grid, old_grid, samples[:, k]) for k in range(samples.shape[1])])
    else:
        resampled = CubicSpline(old_grid, samples, axis=0)(new_grid)
    return resampled.T.reshape(-1)


def classifier_inputs(library: ReachLibrary, n_points: int = 20) -> np.ndarray:
    """Resampled velocity of every movement of a library: the classifier's input matrix.

    Parameters
    ----------
    library : ReachLibrary
        Movements with their padded velocities and lengths.
    n_points : int
        Number of resampled points per axis.

    Returns
    -------
    numpy.ndarray, shape (len(library), 3 * n_points)
        One row per movement, as returned by :func:`resample_movement`.
    """
    inputs = np.empty((len(library), library.velocity.shape[2] * n_points))
    for i in range(len(library)):
        inputs[i] = resample_movement(library.velocity[i], int(library.length[i]), n_points)
    return inputs
