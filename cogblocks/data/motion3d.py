"""Synthetic quasi-periodic 3D hand motion with a known phase, for the 3D phase estimator (section 6).

The real recordings of the deliverable (VICON, arm moved back and forth) are not public.
:func:`reference_primitive` is a stand-in for the reference motion γ_ref of the primitive library and
:func:`generate_motion3d` produces performed trajectories that differ from it the way section 6.1.1
allows: a rotation, a per-axis scaling and a translation, plus the imperfections of a real
recording: the period and the amplitude drift from cycle to cycle, the sensor adds white noise and
the tracker sometimes loses the marker for a few samples (the position is then frozen at the last
sample it delivered). The ground-truth phase is the phase of the reference primitive the hand is
at, 0 at the start of the recording (assumption 3 of section 6.1.1).

Coordinates are in mm in a body frame: x forward, y to the left, z up. Every number below is a
modelling assumption chosen to look like a relaxed arm movement (a 30 cm stroke every 2 s), not a
measured fact.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.integrate import cumulative_trapezoid
from scipy.spatial.transform import Rotation

from cogblocks.sim.params import finite_number, positive_int
from cogblocks.sim.timing import BASE_STEP

__all__ = ["Motion3D", "generate_motion3d", "reference_primitive", "reference_curve"]

_TWO_PI = 2.0 * np.pi
_CENTRE_MM = np.array([350.0, -200.0, 1100.0])  # the hand's mean position in front of the right shoulder
_PHASE_GRID = 256  # phase points per cycle when inverting t(φ)
_DRIFT_CLIP = 2.5  # cycle-to-cycle drifts are Gaussian, clipped at this many standard deviations


def reference_curve(phase: np.ndarray) -> np.ndarray:
    """The reference primitive at the given phases: a forward-back stroke of an arm.

    ``x`` is a 32 cm forward-back stroke (slightly asymmetric: a second harmonic), ``y`` a small
    lateral figure-eight (a 1:2 Lissajous figure with ``x``) and ``z`` an elliptic lift (the hand
    rises on the way forward). Phase 0 is the middle of the stroke, moving forward at full speed.

    Parameters
    ----------
    phase : array_like
        Phases in rad, any shape.

    Returns
    -------
    numpy.ndarray, shape (*phase.shape, 3)
        Positions in mm.
    """
    phi = np.asarray(phase, dtype=np.float64)
    x = 160.0 * np.sin(phi) + 12.0 * np.sin(2.0 * phi + 0.6)
    y = 30.0 * np.sin(2.0 * phi)
    z = 45.0 * (1.0 - np.cos(phi))
    return _CENTRE_MM + np.stack([x, y, z], axis=-1)


def reference_primitive(n_samples: int = 200) -> np.ndarray:
    """The reference motion γ_ref sampled at the phases ``2π i / n_samples``, ``i = 0 … n_samples − 1``.

    Parameters
    ----------
    n_samples : int
        Number of samples of one cycle (200: one 2 s cycle at 100 Hz); at least 3.

    Returns
    -------
    numpy.ndarray, shape (n_samples, 3)
        Positions in mm; the curve is closed (the sample after the last is the first).
    """
    n = positive_int("reference_primitive", "n_samples", n_samples, minimum=3)
    return reference_curve(_TWO_PI * np.arange(n) / n)


@dataclass(frozen=True)
class Motion3D:
    """One performed trajectory and what it was made of.

    Attributes
    ----------
    t : numpy.ndarray, shape (n,)
        Sample times in s, ``k * dt``.
    position : numpy.ndarray, shape (n, 3)
        What the tracker delivers, in mm: noisy, frozen during drop-outs.
    clean_position : numpy.ndarray, shape (n, 3)
        The hand's true position in mm.
    phase : numpy.ndarray, shape (n,)
        Ground-truth phase in rad, wrapped to ``[0, 2π)``; 0 at ``t = 0``.
    dropout : numpy.ndarray of bool, shape (n,)
        True on the samples the tracker froze.
    reference : numpy.ndarray, shape (N, 3)
        The reference primitive γ_ref the trajectory was made from, in mm.
    rotation : numpy.ndarray, shape (3, 3)
        Rotation applied to the primitive (about its centroid).
    scale : numpy.ndarray, shape (3,)
        Per-axis scaling applied before the rotation, along the primitive's axes.
    translation : numpy.ndarray, shape (3,)
        Displacement of the centroid, in mm.
    dt : float
        Sampling time in s.
    """

    t: np.ndarray
    position: np.ndarray
    clean_position: np.ndarray
    phase: np.ndarray
    dropout: np.ndarray
    reference: np.ndarray
    rotation: np.ndarray
    scale: np.ndarray
    translation: np.ndarray
    dt: float

    @property
    def first_period(self) -> int:
        """Number of samples before the ground-truth phase first completes a cycle."""
        unwrapped = np.unwrap(self.phase)
        return int(np.searchsorted(unwrapped, _TWO_PI))


def generate_motion3d(
    seed: int | np.random.Generator = 0,
    duration: float = 30.0,
    dt: float = BASE_STEP,
    *,
    period: float = 2.0,
    period_spread: float = 0.15,
    period_drift: float = 0.05,
    amplitude_drift: float = 0.05,
    rotation_deg: float = 20.0,
    scale_spread: float = 0.2,
    translation_mm: float = 50.0,
    noise_mm: float = 1.0,
    dropout_rate: float = 0.2,
    dropout_samples: tuple[int, int] = (2, 8),
    n_reference: int = 200,
    speed_wobble: float = 0.0,
    dropout_duration: tuple[float, float] | None = None,
) -> Motion3D:
    """Generate one performed 3D trajectory of the reference primitive.

    The trajectory's own mean period is ``period * U(1 - period_spread, 1 + period_spread)``; each
    cycle's period and amplitude then deviate from it by Gaussian relative amounts of standard
    deviation ``period_drift`` and ``amplitude_drift``, interpolated linearly in phase so that the
    speed never jumps. The primitive is scaled along its own axes by ``U(1 - scale_spread,
    1 + scale_spread)`` each, rotated about a random axis by up to ``rotation_deg`` and displaced by
    a Gaussian translation of ``translation_mm`` per axis. Drop-outs start at random (a Poisson
    process of ``dropout_rate`` per second) and freeze the delivered position for a number of
    samples drawn uniformly from ``dropout_samples``.

    Parameters
    ----------
    seed : int or numpy.random.Generator
        Seed of every random choice; the same seed gives identical data.
    duration : float
        Length in s (> 0).
    dt : float
        Sampling time in s (> 0, at most ``period / 10``).
    period : float
        Nominal period in s (> 0).
    period_spread, scale_spread : float
        Half-widths of the uniform spreads of the mean period and of the axis scales, in [0, 0.5].
    period_drift, amplitude_drift : float
        Cycle-to-cycle relative standard deviations, in [0, 0.2].
    rotation_deg : float
        Largest rotation angle in degrees, in [0, 180].
    translation_mm : float
        Standard deviation of the translation per axis in mm (>= 0).
    noise_mm : float
        Standard deviation of the white sensor noise per axis in mm (>= 0).
    dropout_rate : float
        Mean number of drop-outs per second (>= 0).
    dropout_samples : (int, int)
        Shortest and longest drop-out in samples (1 <= shortest <= longest).
    n_reference : int
        Samples of the reference primitive returned with the data (>= 3).
    speed_wobble : float
        Uneven speed within a cycle, in [0, 0.5]: the phase advances at ``1 + speed_wobble · cos(φ + ψ)``
        times its mean speed (ψ random; a cycle lasts ``1 / sqrt(1 − speed_wobble²)`` times longer).
        0 (the default) draws nothing, so a seed gives the same trajectories with or without the option.
    dropout_duration : (float, float), optional
        Shortest and longest drop-out in s (0 < shortest <= longest), in place of
        ``dropout_samples``: ``round(duration / dt)`` samples, at least 1, so that a set of
        trajectories means the same at every rate. ``(0.1, 0.3)`` at 100 Hz is ``(10, 30)``.

    Returns
    -------
    Motion3D

    Raises
    ------
    ValueError
        If a parameter is out of range; the message names it, its value and what is allowed.
    """
    owner = "generate_motion3d"
    duration = finite_number(owner, "duration", duration, low=0.0, low_open=True)
    period = finite_number(owner, "period", period, low=0.0, low_open=True)
    dt = finite_number(owner, "dt", dt, low=0.0, high=period / 10.0, low_open=True)
    period_spread = finite_number(owner, "period_spread", period_spread, low=0.0, high=0.5)
    scale_spread = finite_number(owner, "scale_spread", scale_spread, low=0.0, high=0.5)
    period_drift = finite_number(owner, "period_drift", period_drift, low=0.0, high=0.2)
    amplitude_drift = finite_number(owner, "amplitude_drift", amplitude_drift, low=0.0, high=0.2)
    rotation_deg = finite_number(owner, "rotation_deg", rotation_deg, low=0.0, high=180.0)
    translation_mm = finite_number(owner, "translation_mm", translation_mm, low=0.0)
    noise_mm = finite_number(owner, "noise_mm", noise_mm, low=0.0)
    speed_wobble = finite_number(owner, "speed_wobble", speed_wobble, low=0.0, high=0.5)
    dropout_rate = finite_number(owner, "dropout_rate", dropout_rate, low=0.0)
    if not (isinstance(dropout_samples, tuple) and len(dropout_samples) == 2):
        raise ValueError(f"{owner}: dropout_samples must be a tuple (shortest, longest), got {dropout_samples!r}")
    if dropout_duration is not None:
        if not (isinstance(dropout_duration, tuple) and len(dropout_duration) == 2):
            raise ValueError(f"{owner}: dropout_duration must be a tuple (shortest, longest), got {dropout_duration!r}")
        low = finite_number(owner, "dropout_duration[0]", dropout_duration[0], low=0.0, low_open=True)
        high = finite_number(owner, "dropout_duration[1]", dropout_duration[1], low=low)
        dropout_samples = (max(1, round(low / dt)), max(1, round(high / dt)))
    shortest = positive_int(owner, "dropout_samples[0]", dropout_samples[0])
    longest = positive_int(owner, "dropout_samples[1]", dropout_samples[1], minimum=shortest)
    reference = reference_primitive(n_reference)
    rng = np.random.default_rng(seed)

    n = int(round(duration / dt))
    t = np.arange(n) * dt
    mean_period = period * rng.uniform(1.0 - period_spread, 1.0 + period_spread)
    # enough cycles even if every one of them is as short as the clipped drift allows
    n_cycles = int(np.ceil(duration / (mean_period * (1.0 - _DRIFT_CLIP * period_drift)))) + 2
    cycle_period = mean_period * (1.0 + period_drift * _clipped_normal(rng, n_cycles))
    cycle_amplitude = 1.0 + amplitude_drift * _clipped_normal(rng, n_cycles)
    # the drifting quantities are given at each cycle's middle and interpolated linearly in phase
    phi_grid = np.linspace(0.0, _TWO_PI * n_cycles, _PHASE_GRID * n_cycles + 1)
    cycle_pos = phi_grid / _TWO_PI - 0.5
    period_of_phi = np.interp(cycle_pos, np.arange(n_cycles), cycle_period)
    if speed_wobble > 0.0:  # drawn only then, so that the default trajectories keep their random stream
        period_of_phi = period_of_phi / (1.0 + speed_wobble * np.cos(phi_grid + rng.uniform(0.0, _TWO_PI)))
    t_of_phi = cumulative_trapezoid(period_of_phi / _TWO_PI, phi_grid, initial=0.0)
    phi = np.interp(t, t_of_phi, phi_grid)
    amplitude = np.interp(phi / _TWO_PI - 0.5, np.arange(n_cycles), cycle_amplitude)

    scale = rng.uniform(1.0 - scale_spread, 1.0 + scale_spread, size=3)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    rotation = Rotation.from_rotvec(np.deg2rad(rng.uniform(-rotation_deg, rotation_deg)) * axis).as_matrix()
    translation = rng.normal(scale=translation_mm, size=3)
    centroid = reference.mean(axis=0)
    shape = (reference_curve(phi) - centroid) * scale * amplitude[:, None]
    clean = centroid + translation + shape @ rotation.T

    measured = clean + rng.normal(scale=noise_mm, size=clean.shape)
    dropout = np.zeros(n, dtype=bool)
    n_dropouts = rng.poisson(dropout_rate * duration)
    starts = rng.integers(1, max(n, 2), size=n_dropouts)  # never the first sample: there is nothing to freeze
    lengths = rng.integers(shortest, longest + 1, size=n_dropouts)
    for start, length in zip(starts, lengths, strict=True):
        dropout[start : start + length] = True
    for k in np.flatnonzero(dropout):  # in order, so a long freeze carries the last delivered sample
        measured[k] = measured[k - 1]
    return Motion3D(
        t=t,
        position=measured,
        clean_position=clean,
        phase=np.mod(phi, _TWO_PI),
        dropout=dropout,
        reference=reference,
        rotation=rotation,
        scale=scale,
        translation=translation,
        dt=dt,
    )


def _clipped_normal(rng: np.random.Generator, size: int) -> np.ndarray:
    return np.clip(rng.normal(size=size), -_DRIFT_CLIP, _DRIFT_CLIP)
