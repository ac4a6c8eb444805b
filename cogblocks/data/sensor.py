"""A realistic 1D position sensor watching a human oscillation: any rate, any unit, and the faults of real sensors.

The movement is a human-like oscillation: its phase ``φ`` advances at a frequency that drifts slowly
(log-normal Ornstein-Uhlenbeck, time constant 10 s,
smoothed by a spline through 0.1 s knots) and also wobbles within a cycle; the position is
``c(t) + A(t) w(φ)`` with a drifting centre and amplitude and a waveform ``w`` with small second and third
harmonics. The sensor samples it at ``rate_hz`` with timestamp jitter, in a unit ``scale`` times the
movement's natural one, adds white noise, quantises to a step (so that samples repeat in runs), and has
drop-outs (NaN runs, or runs frozen at the last value) and isolated spikes. The true phase at each
sample's real time is returned with it: ``p = cos φ`` has phase ``φ``, the convention of the phase
estimators.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.interpolate

from cogblocks.data.oscillation import _ou, _range
from cogblocks.sim.params import finite_number

__all__ = ["SensorRecording", "simulate_sensor"]

_OWNER = "simulate_sensor"
_KNOT = 0.1  # s, grid of the slow drifts


@dataclass
class SensorRecording:
    """A simulated sensor stream and its ground truth, one entry per sample.

    Attributes
    ----------
    t : numpy.ndarray
        Real sample times in seconds: ``k / rate_hz`` plus the timestamp jitter.
    value : numpy.ndarray
        What the sensor reports, in its unit: noisy, quantised, NaN or frozen in drop-outs, with spikes.
    phase : numpy.ndarray
        True phase of the movement at ``t``, in rad, in ``[0, 2π)``.
    clean : numpy.ndarray
        The movement at ``t`` in the sensor's unit, without noise, quantisation or faults.
    missing, frozen, spike : numpy.ndarray of bool
        Where ``value`` is NaN, frozen at an earlier sample, or a spike.
    frequency : numpy.ndarray
        Instantaneous frequency of the movement in Hz.
    amplitude : numpy.ndarray
        Instantaneous amplitude (half the peak-to-peak excursion) in the sensor's unit.
    dt : float
        Nominal sampling step ``1 / rate_hz`` in seconds.
    step : float
        Quantisation step in the sensor's unit (0 = none).
    """

    t: np.ndarray
    value: np.ndarray
    phase: np.ndarray
    clean: np.ndarray
    missing: np.ndarray
    frozen: np.ndarray
    spike: np.ndarray
    frequency: np.ndarray
    amplitude: np.ndarray
    dt: float
    step: float

    @property
    def bad(self) -> np.ndarray:
        """True where the sample is not a measurement of the movement (missing, frozen or spike)."""
        return self.missing | self.frozen | self.spike


def simulate_sensor(
    duration: float = 60.0,
    *,
    rate_hz: float = 100.0,
    seed: int | np.random.Generator | None = None,
    scale: float = 1.0,
    freq_range: tuple[float, float] = (0.4, 1.2),
    freq_drift: float = 0.15,
    cycle_wobble: float = 0.1,
    amplitude_drift: float = 0.15,
    harmonics: float = 0.06,
    noise: float = 0.005,
    quantisation: float = 0.0,
    jitter: float = 0.05,
    dropout_rate: float = 3.0,
    dropout_duration: tuple[float, float] = (0.1, 0.5),
    nan_share: float = 0.5,
    spike_rate: float = 2.0,
) -> SensorRecording:
    """Simulate a seeded sensor stream of a 1D human oscillation, with its true phase.

    Amplitudes, noise and the quantisation step are relative to the movement's base amplitude, which is
    drawn in ``[0.5, 2] · scale`` (the centre in ``±5 · scale``): ``scale`` is the unit (1000 for a
    movement of about a metre reported in mm, 0.01 for one of a centimetre reported in m).

    Parameters
    ----------
    duration : float
        Length in seconds (> 0, at least 16 samples).
    rate_hz : float
        Nominal sampling rate in Hz (> 0, at least 4 times the highest frequency).
    seed : int, numpy.random.Generator or None
        Random source; the same seed gives the same stream.
    scale : float
        Unit scale (> 0), see above.
    freq_range : (float, float)
        Range of the movement's frequency in Hz; the base frequency is drawn in it and the drift clipped to it.
    freq_drift : float
        Standard deviation of the slow log-frequency drift (>= 0).
    cycle_wobble : float
        Relative speed variation within a cycle (in ``[0, 0.5]``): the phase speed is multiplied by
        ``1 + cycle_wobble · cos(φ + ψ)`` (a movement faster one way than the other).
    amplitude_drift : float
        Standard deviation of the log-amplitude drift (>= 0, time constant 8 s); the centre drifts by
        20 % of the amplitude (time constant 15 s).
    harmonics : float
        Largest relative amplitude of the second and third harmonics (in ``[0, 0.3]``).
    noise : float
        Standard deviation of the white noise, relative to the base amplitude (>= 0).
    quantisation : float
        Quantisation step relative to the base amplitude (>= 0; 0 = none).
    jitter : float
        Standard deviation of the timestamp jitter, in sampling steps (in ``[0, 0.3]``).
    dropout_rate : float
        Mean number of drop-outs per minute (>= 0), Poisson starts.
    dropout_duration : (float, float)
        Range of drop-out lengths in seconds.
    nan_share : float
        Probability that a drop-out is a NaN run rather than a frozen run (in ``[0, 1]``).
    spike_rate : float
        Mean number of single-sample spikes per minute (>= 0): the sample is displaced by 4-10 base
        amplitudes, either way.

    Returns
    -------
    SensorRecording

    Raises
    ------
    ValueError
        If a parameter is out of range; the message names it, the value and what is allowed.

    Examples
    --------
    >>> rec = simulate_sensor(10.0, rate_hz=40.0, seed=1, quantisation=0.05)
    >>> rec.value.shape, bool(np.any(np.diff(rec.value) == 0.0))
    ((400,), True)
    """
    duration = finite_number(_OWNER, "duration", duration, low=0.0, low_open=True)
    rate_hz = finite_number(_OWNER, "rate_hz", rate_hz, low=0.0, low_open=True)
    dt = 1.0 / rate_hz
    n = int(round(duration * rate_hz))
    if n < 16:
        raise ValueError(f"{_OWNER}: duration must hold at least 16 samples at {rate_hz} Hz, got {duration!r}")
    scale = finite_number(_OWNER, "scale", scale, low=0.0, low_open=True)
    f_lo, f_hi = _range(_OWNER, "freq_range", freq_range, 0.0, 0.25 * rate_hz)
    freq_drift = finite_number(_OWNER, "freq_drift", freq_drift, low=0.0)
    cycle_wobble = finite_number(_OWNER, "cycle_wobble", cycle_wobble, low=0.0, high=0.5)
    amplitude_drift = finite_number(_OWNER, "amplitude_drift", amplitude_drift, low=0.0)
    harmonics = finite_number(_OWNER, "harmonics", harmonics, low=0.0, high=0.3)
    noise = finite_number(_OWNER, "noise", noise, low=0.0)
    quantisation = finite_number(_OWNER, "quantisation", quantisation, low=0.0)
    jitter = finite_number(_OWNER, "jitter", jitter, low=0.0, high=0.3)
    dropout_rate = finite_number(_OWNER, "dropout_rate", dropout_rate, low=0.0)
    d_lo, d_hi = _range(_OWNER, "dropout_duration", dropout_duration, 0.0)
    nan_share = finite_number(_OWNER, "nan_share", nan_share, low=0.0, high=1.0)
    spike_rate = finite_number(_OWNER, "spike_rate", spike_rate, low=0.0)
    rng = np.random.default_rng(seed)

    # the movement on a fine grid (4 points per sample), then read at the jittered sample times
    sub = 4
    fine_dt = dt / sub
    m = n * sub + sub
    t_fine = np.arange(m) * fine_dt

    def drift(tau: float, std: float) -> np.ndarray:
        # an Ornstein-Uhlenbeck path on a 0.1 s grid, splined: slow and smooth, like a person's drift
        knots = np.arange(int(np.ceil(t_fine[-1] / _KNOT)) + 2) * _KNOT
        return scipy.interpolate.CubicSpline(knots, _ou(rng, len(knots), _KNOT, tau, std))(t_fine)

    base_f = rng.uniform(f_lo, f_hi)
    slow_f = np.clip(base_f * np.exp(drift(10.0, freq_drift)), f_lo, f_hi)
    psi = rng.uniform(0.0, 2.0 * np.pi)
    phi = np.empty(m)
    phi[0] = rng.uniform(0.0, 2.0 * np.pi)
    for k in range(1, m):  # the wobble depends on the phase itself: integrate step by step
        speed = 2.0 * np.pi * slow_f[k - 1] * (1.0 + cycle_wobble * np.cos(phi[k - 1] + psi))
        phi[k] = phi[k - 1] + speed * fine_dt
    base_a = rng.uniform(0.5, 2.0) * scale
    amp = base_a * np.exp(drift(8.0, amplitude_drift))
    centre = rng.uniform(-5.0, 5.0) * scale + drift(15.0, 0.2 * base_a)
    h = rng.uniform(0.0, harmonics, size=2)
    hpsi = rng.uniform(0.0, 2.0 * np.pi, size=2)

    def waveform(x: np.ndarray) -> np.ndarray:
        return np.cos(x) + h[0] * np.cos(2.0 * x + hpsi[0]) + h[1] * np.cos(3.0 * x + hpsi[1])

    half_range = 0.5 * np.ptp(waveform(np.linspace(0.0, 2.0 * np.pi, 721)))
    t = np.arange(n) * dt + np.clip(jitter * dt * rng.standard_normal(n), -0.45 * dt, 0.45 * dt)
    t = np.clip(t, 0.0, None)
    phase_t = np.interp(t, t_fine, phi)
    amplitude = np.interp(t, t_fine, amp)
    clean = np.interp(t, t_fine, centre) + amplitude * waveform(phase_t) / half_range
    value = clean + noise * base_a * rng.standard_normal(n)
    step = quantisation * base_a
    if step > 0.0:
        value = np.round(value / step) * step

    spike = np.zeros(n, dtype=bool)
    where = rng.integers(1, n, size=rng.poisson(spike_rate * duration / 60.0))
    value[where] += rng.choice([-1.0, 1.0], size=where.size) * rng.uniform(4.0, 10.0, size=where.size) * base_a
    spike[where] = True
    missing = np.zeros(n, dtype=bool)
    frozen = np.zeros(n, dtype=bool)
    for start in np.sort(rng.integers(1, n, size=rng.poisson(dropout_rate * duration / 60.0))):
        stop = min(n, start + max(1, int(round(rng.uniform(d_lo, d_hi) * rate_hz))))
        if rng.random() < nan_share:
            value[start:stop] = np.nan
            missing[start:stop] = True
        else:
            value[start:stop] = value[start - 1]
            frozen[start:stop] = True
    spike &= ~(missing | frozen)
    frozen &= ~missing
    return SensorRecording(
        t=t,
        value=value,
        phase=np.mod(phase_t, 2.0 * np.pi),
        clean=clean,
        missing=missing,
        frozen=frozen,
        spike=spike,
        frequency=np.interp(t, t_fine[1:], np.diff(phi) / (2.0 * np.pi * fine_dt)),
        amplitude=amplitude,
        dt=dt,
        step=step,
    )
