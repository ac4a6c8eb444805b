"""A still hand reported as still: a rest gate for velocity estimates, and the bound it needs.

A velocity estimated from noisy positions is never exactly zero: at rest its speed is the noise's. A
block downstream that decides "at rest" at a small speed (the amplification architecture's 1 mm/s)
then never sees the hand stop. :class:`RestGate` outputs zero for a velocity whose speed is at or
below a threshold; :func:`rest_speed_bound` gives the speed that a still hand's estimate stays below
with a chosen probability, for a :class:`~cogblocks.sensing.KalmanEstimator` followed by a
Butterworth low-pass (:class:`~cogblocks.blocks.LowPass`), as a threshold for the gate, and
:func:`rest_cutoff` the least smoothing that keeps that speed within a bound.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import scipy.linalg
import scipy.optimize
import scipy.signal
import scipy.stats
from filterpy.common import Q_continuous_white_noise

from cogblocks.sensing.kalman import DEFAULT_PROCESS_NOISE, MODELS, ORDER, axis_transition
from cogblocks.sim import Block, Signal
from cogblocks.sim.params import finite_number, one_of, positive_int
from cogblocks.sim.timing import BASE_STEP

__all__ = ["RestGate", "rest_cutoff", "rest_speed_bound"]

# Samples of the impulse response summed for the noise gain, at least, and per time constant of the low-pass (about
# 1/(2π f) s): after 40 time constants the response has decayed by more than e^-40.
_IMPULSE_SAMPLES = 4000
_TIME_CONSTANTS = 40.0


class RestGate(Block):
    """Zero a velocity whose speed (Euclidean norm) is at or below ``threshold``; pass it unchanged otherwise.

    Ports
    -----
    u : input, shape (n,) or scalar, ``unit``
        The velocity estimate.
    y : output, spec of ``u``
        ``u``, or zeros while at rest.
    rest : output, scalar bool
        Whether this tick's ``u`` was taken for rest.

    Parameters
    ----------
    threshold : float
        Speed at or below which the hand is at rest, in ``unit`` (≥ 0; 0 passes everything but an exact zero).
        :func:`rest_speed_bound` gives one for a tracker's noise.
    unit : str
        Unit of the velocity (``"mm/s"``).

    Notes
    -----
    Bad data policy: a sample with a non-finite element passes unchanged (it is not taken for rest), so that
    the block downstream applies its own policy to it.
    """

    def __init__(self, threshold: float, *, unit: str = "mm/s", period: float | None = None) -> None:
        super().__init__(period=period)
        self.threshold = finite_number(self, "threshold", threshold, low=0.0)
        if not isinstance(unit, str) or not unit:
            raise ValueError(f"RestGate: unit must be a non-empty string, got {unit!r}")
        self.unit = unit
        self.add_input("u", Signal(unit=unit, shape=None))
        self.add_output("y", like="u")
        self.add_output("rest", Signal(dtype=bool), initial=False)

    def output(self, k: int) -> None:
        u = self.u.value
        rest = False
        if np.all(np.isfinite(u)):
            largest = float(np.max(np.abs(u), initial=0.0))
            # scaled by the largest component, so that a huge sample does not overflow the squares
            rest = largest == 0.0 or largest * math.sqrt(float(np.sum((u / largest) ** 2))) <= self.threshold
        self.rest.value[...] = rest
        self.y.value[...] = 0.0 if rest else u


def rest_speed_bound(
    noise: float,
    cutoff: float | None,
    *,
    order: int = 2,
    model: str = "ca",
    process_noise: float | None = None,
    measurement_noise: float | None = None,
    dt: float = BASE_STEP,
    dims: int = 3,
    quantile: float = 0.999,
) -> float:
    """The speed a still hand's velocity estimate stays at or below with probability ``quantile``, in steady state.

    The estimate is a :class:`~cogblocks.sensing.KalmanEstimator` (``model``, ``process_noise``,
    ``measurement_noise``) of positions carrying white Gaussian noise of standard deviation ``noise`` per
    axis, followed by a Butterworth low-pass of ``order`` at ``cutoff`` Hz (``None``: none), as
    :class:`~cogblocks.blocks.LowPass` designs it. In steady state both are linear and time-invariant, so the
    estimate's error per axis is Gaussian with standard deviation ``noise · ‖h‖₂``, ``h`` the impulse
    response from a measurement to the smoothed velocity (the steady-state Kalman gain from the discrete
    Riccati equation, then the filter); its speed over ``dims`` axes is ``‖h‖₂ · noise`` times a chi
    variable with ``dims`` degrees of freedom.

    Parameters
    ----------
    noise : float
        Standard deviation of the position noise per axis (position unit, ≥ 0; 0 gives 0).
    cutoff : float or None
        Cut-off frequency of the low-pass in Hz, below the Nyquist frequency ``1 / (2 dt)``.
    order : int
        Order of the low-pass.
    model, process_noise : str, float
        The Kalman model and its ``q``, as :class:`~cogblocks.sensing.KalmanEstimator` (default its own).
    measurement_noise : float, optional
        The Kalman filter's measurement noise; by default ``noise`` (then it must be positive).
    dt : float
        Sampling step in seconds.
    dims : int
        Number of axes.
    quantile : float
        Probability in (0, 1).

    Returns
    -------
    float
        The speed bound, in the position unit per second.
    """
    name = "rest_speed_bound"
    noise = finite_number(name, "noise", noise, low=0.0)
    model = one_of(name, "model", model, MODELS)
    order = positive_int(name, "order", order)
    dt = finite_number(name, "dt", dt, low=0.0, low_open=True)
    dims = positive_int(name, "dims", dims)
    quantile = finite_number(name, "quantile", quantile, low=0.0, high=1.0, low_open=True, high_open=True)
    q = DEFAULT_PROCESS_NOISE[model] if process_noise is None else process_noise
    q = finite_number(name, "process_noise", q, low=0.0, low_open=True)
    r = noise if measurement_noise is None else measurement_noise
    r = finite_number(name, "measurement_noise", r, low=0.0, low_open=True)
    if cutoff is not None:
        cutoff = finite_number(name, "cutoff", cutoff, low=0.0, high=0.5 / dt, low_open=True, high_open=True)
    if noise == 0.0:
        return 0.0
    m = ORDER[model]
    f = axis_transition(m, dt)
    h = np.eye(1, m)
    # the steady-state prior covariance, then the gain: x⁺ = (I − K H) F x⁺ + K z
    prior = scipy.linalg.solve_discrete_are(f.T, h.T, Q_continuous_white_noise(m, dt, q), np.array([[r * r]]))
    gain = prior @ h.T / (prior[0, 0] + r * r)  # H P Hᵀ is the position variance
    a = (np.eye(m) - gain @ h) @ f
    samples = _IMPULSE_SAMPLES
    if cutoff is not None:
        samples = max(samples, math.ceil(_TIME_CONSTANTS / (2.0 * math.pi * cutoff * dt)))
    state, response = gain[:, 0].copy(), np.empty(samples)
    for k in range(samples):
        response[k] = state[1]  # the velocity estimate's response to a unit measurement at step 0
        state = a @ state
    if cutoff is not None:
        response = scipy.signal.sosfilt(scipy.signal.butter(order, cutoff, fs=1.0 / dt, output="sos"), response)
    spread = noise * float(np.sqrt(np.sum(response**2)))
    return spread * math.sqrt(float(scipy.stats.chi2.ppf(quantile, dims)))


def rest_cutoff(
    noise: float,
    bound: float,
    *,
    highest: float,
    lowest: float = 0.1,
    dt: float = BASE_STEP,
    **options: Any,
) -> float:
    """The highest low-pass cut-off (Hz, at most ``highest``) at which :func:`rest_speed_bound` is at most ``bound``.

    The least smoothing, hence the least lag, that keeps a still hand's smoothed estimate at or below ``bound``
    (with the probability ``quantile`` of ``options``). The bound rises with the cut-off, so the cut-off is the
    root of ``rest_speed_bound(noise, f) = bound`` (Brent's method), clipped to ``[lowest, highest]``: ``highest``
    when even that is quiet enough (no noise, for one), ``lowest`` when nothing above it is.

    Parameters
    ----------
    noise, dt, **options
        As :func:`rest_speed_bound` (``options``: ``order``, ``model``, ``process_noise``, ``measurement_noise``,
        ``dims``, ``quantile``).
    bound : float
        The speed (position unit per second) a still hand's estimate may show (> 0).
    highest, lowest : float
        The range of cut-offs (Hz), ``0 < lowest <= highest < 1 / (2 dt)``.
    """
    name = "rest_cutoff"
    bound = finite_number(name, "bound", bound, low=0.0, low_open=True)
    dt = finite_number(name, "dt", dt, low=0.0, low_open=True)
    highest = finite_number(name, "highest", highest, low=0.0, high=0.5 / dt, low_open=True, high_open=True)
    lowest = finite_number(name, "lowest", lowest, low=0.0, high=highest, low_open=True)

    def excess(cutoff: float) -> float:
        return rest_speed_bound(noise, cutoff, dt=dt, **options) - bound

    if excess(highest) <= 0.0:
        return highest
    if excess(lowest) >= 0.0:
        return lowest
    return float(scipy.optimize.brentq(excess, lowest, highest, xtol=1e-6))
