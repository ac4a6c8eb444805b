"""Angle wrapping, shared by every block that handles phases."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["TWO_PI", "wrap_2pi", "wrap_pi"]

TWO_PI = 2.0 * math.pi


def wrap_2pi(x):
    """Wrap angles to ``[0, 2π)``."""
    return np.mod(x, TWO_PI)


def wrap_pi(x):
    """Wrap angles to ``(-π, π]``."""
    y = np.pi - np.mod(np.pi - np.asarray(x, dtype=float), TWO_PI)
    return float(y) if np.ndim(y) == 0 else y
