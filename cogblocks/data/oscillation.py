"""Synthetic 1D human oscillation (an arm moving back and forth along one axis), for the PoP of Social Connectedness.

The model is an oscillator whose fundamental phase ``φ`` advances at a slowly drifting frequency; the
position is ``p = c(t) + A(t) w(φ)`` with a slowly drifting offset ``c`` and amplitude ``A``, and a
waveform ``w`` made of the fundamental plus small second and third harmonics (the asymmetry of a real
reciprocating movement). Measurement noise, acquisition drop-outs (the tracker repeats its last value)
and optional missing (NaN) samples are added on top. The true phase is ``φ`` wrapped to ``[0, 2π)``,
with the convention of the phase estimator: ``p = cos φ`` has phase ``φ``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from cogblocks.sim.params import finite_number
from cogblocks.sim.timing import BASE_STEP

__all__ = ["Oscillation", "generate_oscillation"]

_OWNER = "generate_oscillation"


@dataclass
class Oscillation:
    """A synthetic 1D oscillation and its ground truth, one entry per sample.

    Attributes
    ----------
    t : numpy.ndarray
        Sample times in seconds, ``k * dt``.
    position : numpy.ndarray
        Measured position in mm: noisy, frozen during drop-outs, NaN where a sample is missing.
    phase : numpy.ndarray
        True phase of the underlying oscillator in rad, in ``[0, 2π)``.
    dropout : numpy.ndarray of bool
        True where the measured position is a frozen repeat of an earlier sample.
    clean : numpy.ndarray
        The noisy position before drop-outs and missing samples were applied.
    frequency : numpy.ndarray
        Instantaneous frequency of the oscillator in Hz.
    amplitude : numpy.ndarray
        Instantaneous amplitude (half the peak-to-peak excursion of the waveform) in mm.
    dt : float
        Sampling time in seconds.
    """

    t: np.ndarray
    position: np.ndarray
    phase: np.ndarray
    dropout: np.ndarray
    clean: np.ndarray
    frequency: np.ndarray
    amplitude: np.ndarray
    dt: float


def _range(owner: str, name: str, value: Any, low: float, high: float | None = None) -> tuple[float, float]:
    """Validate a ``(lo, hi)`` pair with ``low < lo <= hi`` (and ``hi <= high`` if given); errors name ``owner``."""
    allowed = f"a pair (lo, hi) with {low} < lo <= hi" + (f" <= {high}" if high is not None else "")
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"{owner}: {name} must be {allowed}, got {value!r}") from None
    if not (np.isfinite(lo) and np.isfinite(hi) and low < lo <= hi and (high is None or hi <= high)):
        raise ValueError(f"{owner}: {name} must be {allowed}, got {value!r}")
    return lo, hi


def _ou(rng: np.random.Generator, n: int, dt: float, tau: float, std: float) -> np.ndarray:
    """A stationary Ornstein-Uhlenbeck path (time constant ``tau``, standard deviation ``std``)."""
    decay = np.exp(-dt / tau)
    kicks = rng.standard_normal(n) * std * np.sqrt(1.0 - decay**2)
    x = np.empty(n)
    x[0] = rng.standard_normal() * std
    for k in range(1, n):
        x[k] = decay * x[k - 1] + kicks[k]
    return x


def generate_oscillation(
    duration: float = 60.0,
    *,
    dt: float = BASE_STEP,
    seed: int | np.random.Generator | None = None,
    freq_range: tuple[float, float] = (0.4, 1.2),
    freq_drift: float = 0.15,
    amplitude_range: tuple[float, float] = (100.0, 300.0),
    amplitude_drift: float = 0.15,
    offset_drift: float = 20.0,
    harmonics: float = 0.08,
    noise_std: float = 1.0,
    dropout_rate: float = 4.0,
    dropout_duration: tuple[float, float] = (0.1, 0.5),
    nan_rate: float = 0.0,
) -> Oscillation:
    """Generate a realistic, seeded 1D back-and-forth arm movement.

    Parameters
    ----------
    duration : float
        Length in seconds (> 0, at least two samples).
    dt : float
        Sampling time in seconds (> 0; 0.01 s is the engine's base step).
    seed : int, numpy.random.Generator or None
        Random source; the same seed gives the same signal.
    freq_range : (float, float)
        Frequencies in Hz. The base frequency is drawn uniformly in the range; the instantaneous
        frequency drifts around it (log-normal Ornstein-Uhlenbeck, time constant 10 s) and is clipped
        to the range.
    freq_drift : float
        Standard deviation of the log-frequency drift (>= 0; 0.15 means about ±15 %).
    amplitude_range : (float, float)
        Amplitudes in mm, drawn and clipped like the frequency (time constant 8 s).
    amplitude_drift : float
        Standard deviation of the log-amplitude drift (>= 0).
    offset_drift : float
        Standard deviation in mm of the slow drift of the centre of the movement (time constant 15 s);
        the centre itself is drawn uniformly in ±500 mm.
    harmonics : float
        Largest relative amplitude of the second and third harmonics, in [0, 0.3]; each is drawn
        uniformly in ``[0, harmonics]`` with a random phase.
    noise_std : float
        Standard deviation of the white measurement noise in mm (>= 0).
    dropout_rate : float
        Mean number of drop-outs per minute (>= 0); their starts form a Poisson process.
    dropout_duration : (float, float)
        Range of drop-out lengths in seconds; each is drawn uniformly in it.
    nan_rate : float
        Probability in [0, 1) that a sample is missing (NaN), independently per sample.

    Returns
    -------
    Oscillation
        Times, measured position, true phase, drop-out mask and the ground truth.

    Raises
    ------
    ValueError
        If a parameter is out of range; the message names it, the value and what is allowed.

    Examples
    --------
    >>> osc = generate_oscillation(10.0, seed=1)
    >>> osc.position.shape, bool(osc.dropout.any())
    ((1000,), True)
    """
    duration = finite_number(_OWNER, "duration", duration, low=0.0, low_open=True)
    dt = finite_number(_OWNER, "dt", dt, low=0.0, low_open=True)
    n = int(round(duration / dt))
    if n < 2:
        raise ValueError(f"{_OWNER}: duration must hold at least two samples of dt={dt}, got {duration!r}")
    f_lo, f_hi = _range(_OWNER, "freq_range", freq_range, 0.0, 0.5 / dt)
    a_lo, a_hi = _range(_OWNER, "amplitude_range", amplitude_range, 0.0)
    freq_drift = finite_number(_OWNER, "freq_drift", freq_drift, low=0.0)
    amplitude_drift = finite_number(_OWNER, "amplitude_drift", amplitude_drift, low=0.0)
    offset_drift = finite_number(_OWNER, "offset_drift", offset_drift, low=0.0)
    harmonics = finite_number(_OWNER, "harmonics", harmonics, low=0.0, high=0.3)
    noise_std = finite_number(_OWNER, "noise_std", noise_std, low=0.0)
    dropout_rate = finite_number(_OWNER, "dropout_rate", dropout_rate, low=0.0)
    d_lo, d_hi = _range(_OWNER, "dropout_duration", dropout_duration, 0.0)
    nan_rate = finite_number(_OWNER, "nan_rate", nan_rate, low=0.0, high=1.0, high_open=True)
    rng = np.random.default_rng(seed)

    t = np.arange(n) * dt
    frequency = np.clip(rng.uniform(f_lo, f_hi) * np.exp(_ou(rng, n, dt, 10.0, freq_drift)), f_lo, f_hi)
    phi = rng.uniform(0.0, 2.0 * np.pi) + 2.0 * np.pi * dt * np.concatenate(([0.0], np.cumsum(frequency[:-1])))
    amplitude = np.clip(rng.uniform(a_lo, a_hi) * np.exp(_ou(rng, n, dt, 8.0, amplitude_drift)), a_lo, a_hi)
    offset = rng.uniform(-500.0, 500.0) + _ou(rng, n, dt, 15.0, offset_drift)

    h = rng.uniform(0.0, harmonics, size=2)
    psi = rng.uniform(0.0, 2.0 * np.pi, size=2)

    def waveform(x: np.ndarray) -> np.ndarray:
        return np.cos(x) + h[0] * np.cos(2.0 * x + psi[0]) + h[1] * np.cos(3.0 * x + psi[1])

    grid = waveform(np.linspace(0.0, 2.0 * np.pi, 721))
    half_range = 0.5 * (grid.max() - grid.min())  # so that ``amplitude`` is half the peak-to-peak excursion
    clean = offset + amplitude * waveform(phi) / half_range + noise_std * rng.standard_normal(n)

    position = clean.copy()
    dropout = np.zeros(n, dtype=bool)
    n_dropouts = rng.poisson(dropout_rate * duration / 60.0)
    for start in np.sort(rng.integers(1, n, size=n_dropouts)):
        stop = min(n, start + max(1, int(round(rng.uniform(d_lo, d_hi) / dt))))
        position[start:stop] = position[start - 1]
        dropout[start:stop] = True
    position[rng.random(n) < nan_rate] = np.nan
    return Oscillation(
        t=t,
        position=position,
        phase=np.mod(phi, 2.0 * np.pi),
        dropout=dropout,
        clean=clean,
        frequency=frequency,
        amplitude=amplitude,
        dt=dt,
    )
