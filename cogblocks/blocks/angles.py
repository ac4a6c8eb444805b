"""Angle wrapping, shared by every block that handles phases."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["TWO_PI", "wrap_2pi", "wrap_angle", "wrap_pi"]

TWO_PI = 2.0 * math.pi


def wrap_angle(x: float) -> float:
    """Wrap one angle to ``[0, 2π)``; fast for Python floats.

    ``x % 2π`` alone returns 2π for tiny negative ``x`` (rounding), which is
    outside the interval.
    """
    y = x % TWO_PI
    return y if y < TWO_PI else 0.0


def wrap_2pi(x):
    """Wrap angles to ``[0, 2π)`` (arrays or scalars)."""
    y = np.mod(x, TWO_PI)
    if np.ndim(y) == 0:
        return float(y) if y < TWO_PI else 0.0
    y[y >= TWO_PI] = 0.0
    return y


def wrap_pi(x):
    """Wrap angles to ``(-π, π]``."""
    y = np.pi - np.mod(np.pi - np.asarray(x, dtype=float), TWO_PI)
    return float(y) if np.ndim(y) == 0 else y
