"""Synthetic recordings of a group moving their arms, from the phases they move at (for tests and examples).

Each participant's hand follows the reference stroke (:func:`~cogblocks.data.motion3d.reference_curve`)
at the phase given for them, placed 1 m apart along y, with white sensor noise: a recording whose
phases are known, so that an analysis of it can be checked against them.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from cogblocks.data.markers import MarkerRecording
from cogblocks.data.motion3d import reference_curve
from cogblocks.sim.timing import BASE_STEP

__all__ = ["group_recording"]


def group_recording(
    theta: np.ndarray,
    dt: float = BASE_STEP,
    *,
    names: Sequence[str] | None = None,
    noise_mm: float = 1.0,
    seed: int | np.random.Generator = 0,
    events: Sequence[tuple[str, float]] = (),
) -> MarkerRecording:
    """A recording of N hands moving at the phases ``theta``.

    Parameters
    ----------
    theta : numpy.ndarray, shape (N, n)
        Each participant's phase in rad at each sample (wrapped or not).
    dt : float
        Sampling time in s.
    names : sequence of str, optional
        Marker names (``P1``, ``P2``, ... by default).
    noise_mm : float
        Standard deviation of the white noise on every coordinate, in mm (>= 0).
    seed : int or numpy.random.Generator
        Seed of that noise.
    events : sequence of (str, float)
        Events of the recording (label, time in s), e.g. the start of each condition.

    Returns
    -------
    MarkerRecording
        Points in mm, ``t = k dt``.
    """
    theta = np.asarray(theta, dtype=np.float64)
    if theta.ndim != 2 or theta.shape[1] < 2 or not np.isfinite(theta).all():
        raise ValueError(f"group_recording: theta must be a finite (N, n >= 2) array, got shape {theta.shape}")
    if not (np.isfinite(noise_mm) and noise_mm >= 0):
        raise ValueError(f"group_recording: noise_mm must be >= 0, got {noise_mm!r}")
    n_people, n = theta.shape
    names = tuple(names) if names is not None else tuple(f"P{i + 1}" for i in range(n_people))
    if len(names) != n_people:
        raise ValueError(f"group_recording: {len(names)} names for {n_people} participants")
    rng = np.random.default_rng(seed)
    points = reference_curve(theta.T)  # (n, N, 3)
    points[..., 1] += 1000.0 * np.arange(n_people)  # side by side, 1 m apart
    points += rng.normal(0.0, noise_mm, points.shape)
    return MarkerRecording(points, dt * np.arange(n), 1.0 / dt, names, tuple(events), "<synthetic group>")
