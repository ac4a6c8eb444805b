"""The Kalman front end of the 1D phase estimator, with its noise scaled to the signal's own amplitude."""

from __future__ import annotations

import math

import numpy as np
from filterpy.common import Q_continuous_white_noise

from cogblocks.sensing.kalman import KalmanEstimator
from cogblocks.sim.params import finite_number

__all__ = ["ScaledKalman"]

#: Mean absolute deviation of the movements the mm defaults of KalmanEstimator were chosen for (a 200 mm
#: sinusoid: 2/π of its amplitude).
REFERENCE_SCALE = 200.0 * 2.0 / math.pi


class ScaledKalman(KalmanEstimator):
    """A constant-acceleration :class:`~cogblocks.sensing.KalmanEstimator` on one axis whose noise follows the signal.

    The defaults of ``KalmanEstimator`` are for arm movements of 100-300 mm. This block measures the
    signal's scale as the mean absolute deviation ``s`` of its valid samples from their mean over the
    first ``warmup`` seconds (at least 2 samples; until the signal moves, its magnitude), and uses
    ``q = q₀ (s / s₀)²`` and ``σ = σ₀ s / s₀``,
    where ``q₀, σ₀`` are the mm defaults and ``s₀`` the scale they were chosen for (127 mm); the
    scale is then kept. So the filter means the same in any unit. Repeated samples are measurements
    (``freeze_frames=None``): a quantised sensor repeats on purpose, and the phase estimator behind
    recognises drop-outs itself.

    Ports, parameters and bad data policy are those of ``KalmanEstimator("ca", dims=1,
    freeze_frames=None)``; additionally:

    Parameters
    ----------
    warmup : float
        Seconds over which the scale is measured (> 0).

    Notes
    -----
    Bad data policy: that of ``KalmanEstimator`` (missing, spikes, jumps); a missing sample does not
    enter the scale.
    """

    def __init__(self, *, unit: str = "mm", warmup: float = 3.0, period: float | None = None) -> None:
        super().__init__("ca", dims=1, unit=unit, freeze_frames=None, period=period)
        self.warmup = finite_number(self, "warmup", warmup, low=0.0, low_open=True)
        self.add_state("n_seen", 0)
        self.add_state("mean", 0.0)
        self.add_state("mad", 0.0)
        self.add_state("ratio", 1.0)  # s / s0

    def setup(self) -> None:
        super().setup()
        self._q0, self._r0 = self.process_noise, self.measurement_noise
        self._warm_ticks = max(2, math.ceil(self.warmup / self.dt))
        # the noise in force is a cache of the declared `ratio`, re-applied by every output()
        self.add_scratch("_applied", 1.0)
        for name in ("process_noise", "measurement_noise", "_prior_var"):
            self.add_scratch(name, getattr(self, name))

    def _apply(self, ratio: float) -> None:
        """Scale the filter's noise to ``ratio`` times the reference scale."""
        if ratio == self._applied:
            return
        self.process_noise, self.measurement_noise = self._q0 * ratio**2, self._r0 * ratio
        kf = self._kf
        kf.Q = Q_continuous_white_noise(self.order, self.dt, self.process_noise, block_size=1)
        kf.R = self.measurement_noise**2 * np.eye(1)
        one_second = np.diag(Q_continuous_white_noise(self.order, 1.0, self.process_noise))
        self._prior_var = np.concatenate([[self.measurement_noise**2], one_second[1:]])
        self._applied = ratio

    def output(self, k: int) -> None:
        x = float(self.p.value)
        if self.n_seen == 0 and math.isfinite(x) and 0.0 < abs(x) < 1e150:
            self._apply(abs(x) / REFERENCE_SCALE)  # the filter starts at this sample: in its own scale
        else:
            self._apply(self.ratio)
        super().output(k)

    def update(self, k: int) -> None:
        super().update(k)
        x = float(self.p.value)
        n = self.n_seen
        if n >= self._warm_ticks or not (math.isfinite(x) and abs(x) < 1e150):
            return
        # running mean, and mean absolute deviation from the running mean (close to that from the final one)
        self.mean += (x - self.mean) / (n + 1)
        self.mad += (abs(x - self.mean) - self.mad) / (n + 1)
        self.n_seen = n + 1
        # until the signal has moved, its magnitude is the only scale there is (0 has none)
        scale = self.mad if self.mad > 0.0 else abs(x)
        if scale > 0.0:
            self.ratio = scale / REFERENCE_SCALE
