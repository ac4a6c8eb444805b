"""The live-tracker front end of the amplification diagram: tracked positions through a Kalman estimator.

On a live stream only the marker's positions arrive, with the tracker's noise. :func:`add_kalman_front_end` adds
to a diagram the blocks that turn a replayed movement into what such a stream gives the L2 architecture: the
positions plus seeded white noise (``tracked``), a 3D :class:`~cogblocks.sensing.KalmanEstimator` (``tracking``)
and, by default, a low-pass on its velocity (``smooth``) and a rest gate (``still``).

Why the last two (docs/validation/amplification.md, Claim 2): the architecture emits the velocity it is
given, plus its correction, and takes a speed at or below 1 mm/s for rest. The Kalman estimate of noisy positions
carries tens of mm/s of noise (about 20 mm/s per axis at 0.3 mm), which the judges read as fear (the jerk among
others), and never falls to 1 mm/s, so the hand is never seen to stop and a fear plan is stretched to the whole
window. The low-pass trades that noise for a few samples of lag; the gate reports as rest what a still hand's
smoothed estimate shows (:func:`~cogblocks.sensing.rest_speed_bound`).
"""

from __future__ import annotations

import numpy as np

from cogblocks.blocks import LowPass, Playback
from cogblocks.sensing import KalmanEstimator, RestGate, rest_cutoff, rest_speed_bound
from cogblocks.sim import Diagram
from cogblocks.sim.params import finite_number
from cogblocks.sim.ports import Output

__all__ = [
    "AUTO_HIGHEST_HZ",
    "AUTO_REST_BOUND",
    "REST_QUANTILE",
    "SMOOTHING_HZ",
    "add_kalman_front_end",
    "checked_cutoff",
    "smoothing_cutoff",
]

#: The low-pass on the Kalman front end's velocity: ``"auto"`` (:func:`smoothing_cutoff`), chosen on validation
#: libraries 3018-3020 over fixed cut-offs of 2, 3 and 5 Hz (docs/validation/amplification.md, Claim 2).
SMOOTHING_HZ: float | str | None = "auto"
#: Probability with which a still hand's smoothed velocity estimate stays at or below the rest gate's threshold.
REST_QUANTILE = 0.999
#: ``smoothing_hz="auto"``: the least smoothing, at most this cut-off (Hz), that keeps a still hand's smoothed
#: estimate at or below ``AUTO_REST_BOUND`` (mm/s; with probability ``REST_QUANTILE``), :func:`smoothing_cutoff`.
AUTO_HIGHEST_HZ = 3.0
AUTO_REST_BOUND = 12.0
#: The Kalman filter's measurement noise never goes below this (mm): a noise-free replay is still a tracker.
_MIN_MEASUREMENT_NOISE = 0.1


def checked_cutoff(owner: str, smoothing_hz: float | str | None, dt: float) -> float | str | None:
    """``smoothing_hz`` as a float in (0, 1/(2 dt)) Hz, ``"auto"`` or None; otherwise a ValueError naming ``owner``."""
    if smoothing_hz is None or (isinstance(smoothing_hz, str) and smoothing_hz == "auto"):
        return smoothing_hz
    try:
        return finite_number(owner, "smoothing_hz", smoothing_hz, low=0.0, high=0.5 / dt, low_open=True, high_open=True)
    except ValueError:
        allowed = f"a finite number in (0.0, {0.5 / dt!r}), 'auto' or None"
        raise ValueError(f"{owner}: smoothing_hz must be {allowed}, got {smoothing_hz!r}") from None


def smoothing_cutoff(smoothing_hz: float | str, noise_mm: float, dt: float) -> float:
    """The low-pass cut-off (Hz) for ``smoothing_hz``: itself, or for ``"auto"`` the one chosen from ``noise_mm``.

    ``"auto"``: :func:`~cogblocks.sensing.rest_cutoff` with :data:`AUTO_REST_BOUND` and :data:`AUTO_HIGHEST_HZ`:
    the tracker's noise sets the smoothing, so that a quiet tracker is not smoothed (and delayed) more than it needs.
    """
    if smoothing_hz != "auto":
        return float(smoothing_hz)
    return rest_cutoff(
        noise_mm, AUTO_REST_BOUND, highest=AUTO_HIGHEST_HZ, dt=dt, quantile=REST_QUANTILE,
        measurement_noise=max(noise_mm, _MIN_MEASUREMENT_NOISE),
    )  # fmt: skip


def add_kalman_front_end(
    d: Diagram, position: np.ndarray, noise_mm: float, seed: int, smoothing_hz: float | str | None, dt: float
) -> tuple[Output, Output]:
    """Add the tracker's blocks for ``position`` (T, 3) to ``d``; return the position and velocity estimates.

    Parameters
    ----------
    d : Diagram
        Receives the blocks ``tracked``, ``tracking`` and (with ``smoothing_hz``) ``smooth`` and ``still``.
    position : numpy.ndarray, shape (T, 3)
        The movement's positions (mm), one row per tick.
    noise_mm : float
        Standard deviation (mm) of the white noise added per axis, seeded by ``seed`` (≥ 0).
    seed : int
        Seed of the noise.
    smoothing_hz : float, "auto" or None
        Cut-off (Hz) of the second-order Butterworth low-pass on the estimated velocity, or ``"auto"``
        (:func:`smoothing_cutoff`); ``None``: the estimate as it is, without low-pass or rest gate.
    dt : float
        The diagram's step (s), for the rest gate's threshold.
    """
    noise = np.random.default_rng(seed).normal(scale=noise_mm, size=position.shape) if noise_mm else 0.0
    tracked = d.add("tracked", Playback(position + noise, unit="mm", at_end="hold"))
    # noise-free replays repeat the resting position exactly: that is a still hand, not a frozen tracker
    freeze = 2 if noise_mm > 0 else None
    measurement_noise = max(noise_mm, _MIN_MEASUREMENT_NOISE)
    tracking = d.add("tracking", KalmanEstimator(model="ca", measurement_noise=measurement_noise, freeze_frames=freeze))
    d.connect(tracked.y, tracking.p)
    if smoothing_hz is None:
        return tracking.p_hat, tracking.v_hat
    cutoff = smoothing_cutoff(smoothing_hz, noise_mm, dt)
    threshold = rest_speed_bound(noise_mm, cutoff, measurement_noise=measurement_noise, dt=dt, quantile=REST_QUANTILE)
    smooth, still = d.add("smooth", LowPass(cutoff)), d.add("still", RestGate(threshold))
    d.connect(tracking.v_hat, smooth.u)
    d.connect(smooth.y, still.u)
    return tracking.p_hat, still.y
