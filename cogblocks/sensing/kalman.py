"""State estimation of motion-capture positions: a gated Kalman filter and a noise fit.

Motion-capture streams arrive noisy, with missing frames (NaN), values frozen
when tracking drops, spikes and a transmission delay. :class:`KalmanEstimator`
turns such a stream into position, velocity and acceleration estimates with a
flag telling which frames were predicted rather than measured;
:func:`fit_noise` estimates its noise parameters from a recording.

Both use the continuous white-noise kinematic models, per axis:

* ``"cv"`` (constant velocity): the acceleration is white noise of spectral
  density ``q`` (unit²/s³);
* ``"ca"`` (constant acceleration): the jerk is white noise of spectral density
  ``q`` (unit²/s⁵).

The process covariance over a step ``dt`` is the exact discretisation,
``filterpy.common.Q_continuous_white_noise(order, dt, q)``, so ``q`` does not
depend on the sampling rate."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import scipy.optimize
import scipy.stats
from filterpy.common import Q_continuous_white_noise
from filterpy.kalman import KalmanFilter

from cogblocks.sim import Block, Signal
from cogblocks.sim.params import finite_number, one_of, positive_int

__all__ = ["DEFAULT_PROCESS_NOISE", "MODELS", "ORDER", "KalmanEstimator", "axis_transition", "fit_noise"]

#: The kinematic models: constant velocity, constant acceleration.
MODELS = ("cv", "ca")
#: Number of kinematic states per axis (position, velocity[, acceleration]).
ORDER = {"cv": 2, "ca": 3}
#: Defaults for human arm motion in millimetres (0.5-1 Hz oscillations of 100-300 mm at 100 Hz),
#: chosen on benchmarks/l1_delay.py; other units or motions need their own (see fit_noise).
DEFAULT_PROCESS_NOISE = {"cv": 3e6, "ca": 1e8}
_DEFAULT_MEASUREMENT_NOISE = 2.0
# Var(Δ^m_L x) = c_m q (L dt)^(2m-1) + C(2m, m) r for the order-m model sampled every dt with white
# measurement noise of variance r: c_m = ∫ B_{m-1}(u)² du, the squared norm of the cardinal B-spline of
# degree m-1 that the m-fold difference of an m-fold integral applies to the white input.
_PROCESS_FACTOR = {2: 2.0 / 3.0, 3: 11.0 / 20.0}
# Median of a chi-square variable with one degree of freedom: median(d²) / this estimates E[d²] for Gaussian d.
_CHI2_1_MEDIAN = float(scipy.stats.chi2.ppf(0.5, 1))


# A position beyond this (in the position unit, e.g. 1000 km in mm) is a corrupted sample, not a measurement.
_IMPLAUSIBLE = 1e9


class KalmanEstimator(Block):
    """Gated Kalman filter of positions with constant-velocity or constant-acceleration model.

    Each axis follows the kinematic model ``model`` (see the module docstring);
    the axes share nothing but the innovation gate. The filter is a
    ``filterpy.kalman.KalmanFilter`` whose state ``x`` and covariance ``P`` are
    declared block state (pushed into the filterpy object at every use), so
    ``state_dict``/``load_state_dict``/``reset`` cover it.

    Ports
    -----
    p : input, scalar or shape (n,), ``unit``
        Measured positions (3-D markers have shape (3,)). Read at the same tick.
    p_hat : output, spec of ``p``
        Estimated position.
    v_hat : output, shape of ``p``, ``unit + "/s"``
        Estimated velocity.
    a_hat : output, shape of ``p``, ``unit + "/s^2"``
        Estimated acceleration (zeros for the ``"cv"`` model).
    predicted : output, scalar bool
        True when this frame's estimate is a prediction: the sample was missing,
        frozen or rejected by the gate (and before the first sample).

    Parameters
    ----------
    model : {"cv", "ca"}
        Constant velocity or constant acceleration.
    process_noise : float, optional
        Spectral density ``q`` of the white acceleration (``"cv"``, unit²/s³) or
        jerk (``"ca"``, unit²/s⁵). Defaults to ``{cv: 3e6, ca: 1e8}[model]``,
        tuned for human arm motion in millimetres; see :func:`fit_noise`.
    measurement_noise : float
        Standard deviation of the measurement noise, in ``unit`` (2 mm by default).
    dims : int, optional
        Number of axes: 1 gives a scalar input, n > 1 a vector of shape (n,).
        Inferred from the driving signal when omitted.
    unit : str
        Unit of the positions.
    gate : float or None
        Probability of the chi-square innovation gate: a measurement whose
        normalised innovation squared ``yᵀ S⁻¹ y`` exceeds the ``gate`` quantile
        of the chi-square law with ``n`` degrees of freedom is rejected (0.999 by
        default: one false rejection in 1000 good frames when the model holds).
        ``None`` accepts every finite measurement.
    max_rejections : int
        Consecutive rejections after which the filter re-initialises (see Notes);
        5 by default.
    freeze_frames : int or None
        A sample identical to each of the ``freeze_frames`` samples before it is
        treated as missing (2 by default); ``None`` never does.

    Notes
    -----
    Bad data policy, frame by frame:

    * **Missing**: a sample with any non-finite component (NaN or inf), or
      one beyond 1e9 in the position unit (no tracker reports that: it is a
      corrupted value), is missing as a whole; the filter predicts only and
      ``predicted`` is True.
      Missing frames neither count as nor reset consecutive rejections.
    * **Frozen**: trackers that lose a marker often repeat its last value. A
      sample bit-identical to the ``freeze_frames`` samples before it is
      treated as missing, as are the further copies (missing frames in
      between neither break nor extend the run); the first
      ``freeze_frames - 1`` copies are still used (a stream sampled slower than
      the block and held in between repeats samples on purpose: raise
      ``freeze_frames`` above its repeat count, or run the block at its period).
      Once a run is confirmed frozen the filter rewinds to the prediction that
      ignored those first copies, so the whole run counts as missing.
    * **Spikes**: a measurement failing the innovation gate is rejected; the
      frame is predicted and ``predicted`` is True.
    * **Jumps**: a real jump (marker relabelled, unmodelled fast move) would
      be rejected forever. On the ``max_rejections``-th consecutive rejection
      the filter re-initialises from the rejected measurements themselves (see
      below) and that frame is accepted.
    * **(Re-)initialisation**: before any usable sample (finite and below 1e9) the outputs are NaN.
      The filter starts at the first valid sample with the prior "position
      measured, velocity (and acceleration) zero with the spread the model
      accumulates in one second": variances ``q`` (cv velocity) or
      ``q/3`` and ``q`` (ca velocity and acceleration). A re-initialisation
      starts from that prior at the oldest of the last ``max_rejections`` valid
      samples (repeated values left out) and runs the filter, ungated, through
      them to the current one.

    Over a long gap the ``"ca"`` model extrapolates quadratically: predictions
    drift faster than with ``"cv"``.

    The measurement step runs in :meth:`output` (the estimate of tick k needs
    the sample of tick k) without changing state; :meth:`update` commits it and
    predicts to the block's next tick.
    """

    def __init__(
        self,
        model: str = "cv",
        *,
        process_noise: float | None = None,
        measurement_noise: float = _DEFAULT_MEASUREMENT_NOISE,
        dims: int | None = None,
        unit: str = "mm",
        gate: float | None = 0.999,
        max_rejections: int = 5,
        freeze_frames: int | None = 2,
        period: float | None = None,
    ) -> None:
        super().__init__(period=period)
        self.model = one_of(self, "model", model, MODELS)
        self.order = ORDER[model]
        if process_noise is None:
            process_noise = DEFAULT_PROCESS_NOISE[model]
        self.process_noise = finite_number(self, "process_noise", process_noise, low=0.0, low_open=True)
        self.measurement_noise = finite_number(self, "measurement_noise", measurement_noise, low=0.0, low_open=True)
        self.dims = None if dims is None else positive_int(self, "dims", dims)
        if not isinstance(unit, str) or not unit:
            raise ValueError(f"KalmanEstimator: unit must be a non-empty string, got {unit!r}")
        self.unit = unit
        if gate is not None:
            gate = finite_number(self, "gate", gate, low=0.0, high=1.0, low_open=True, high_open=True)
        self.gate = gate
        self.max_rejections = positive_int(self, "max_rejections", max_rejections)
        self.freeze_frames = None if freeze_frames is None else positive_int(self, "freeze_frames", freeze_frames)
        self.add_input("p", Signal(shape=None if dims is None else _shape_of(self.dims), unit=unit))
        self.add_output("p_hat", like="p", initial=np.nan)
        self.add_output("v_hat", like="p", unit=f"{unit}/s", initial=np.nan)
        self.add_output("a_hat", like="p", unit=f"{unit}/s^2", initial=np.nan)
        self.add_output("predicted", Signal(dtype=bool), initial=True)
        # the arrays are sized in setup(), once the number of axes is known
        self.add_state("x", np.zeros(0))
        self.add_state("P", np.zeros((0, 0)))
        self.add_state("initialised", False)
        self.add_state("rejections", 0)
        self.add_state("repeats", 0)
        self.add_state("last_raw", np.zeros(0))
        # the latest valid samples and their own-tick indices, oldest first, for re-initialisation
        self.add_state("buf_z", np.zeros((0, 0)))
        self.add_state("buf_n", np.zeros(0, dtype=np.int64))
        self.add_state("n_buf", 0)
        # the prediction that ignores the copies of a run not yet confirmed frozen
        self.add_state("shadow_x", np.zeros(0))
        self.add_state("shadow_P", np.zeros((0, 0)))
        self.add_state("has_shadow", False)

    def setup(self) -> None:
        shape = self.p.spec.shape
        if len(shape) > 1 or shape == (0,):
            raise self._fail(f"p must be a scalar or a vector of positions, got shape {shape}")
        n = 1 if shape == () else shape[0]
        self.n = n
        order = self.order
        kf = KalmanFilter(dim_x=order * n, dim_z=n)
        kf.F = self._transition(self.dt)
        kf.Q = Q_continuous_white_noise(order, self.dt, self.process_noise, block_size=n)
        kf.H = np.kron(np.eye(n), np.eye(1, order))
        kf.R = self.measurement_noise**2 * np.eye(n)
        self.add_scratch("_kf", kf)  # the filter's matrices; its x and P are loaded from the state every tick
        one_second = np.diag(Q_continuous_white_noise(order, 1.0, self.process_noise))
        self._prior_var = np.tile(np.concatenate([[self.measurement_noise**2], one_second[1:]]), n)
        self.gate_threshold = math.inf if self.gate is None else float(scipy.stats.chi2.ppf(self.gate, n))
        size = self.max_rejections - 1  # what a re-initialisation replays besides the current sample
        self.add_state("x", np.zeros(order * n))
        self.add_state("P", np.zeros((order * n, order * n)))
        self.add_state("last_raw", np.full(n, np.nan))
        self.add_state("buf_z", np.zeros((size, n)))
        self.add_state("buf_n", np.zeros(size, dtype=np.int64))
        self.add_state("shadow_x", np.zeros(order * n))
        self.add_state("shadow_P", np.zeros((order * n, order * n)))
        # what output() decided, for update() to commit
        self.add_scratch("_z", np.zeros(n))
        for name, value in (("_finite", False), ("_valid", False), ("_repeats_next", 0), ("_rejections_next", 0)):
            self.add_scratch(name, value)
        self.add_scratch("_post", None)  # the tick's posterior, committed in update()

    def _transition(self, dt: float) -> np.ndarray:
        return np.kron(np.eye(self.n), axis_transition(self.order, dt))

    # -- the tick --------------------------------------------------------------
    def output(self, k: int) -> None:
        z = self._z
        z[...] = self.p.value.reshape(-1)
        # abs(nan) < bound is False, so one comparison catches NaN, inf and corrupted huge values
        finite = self._finite = bool((np.abs(z) < _IMPLAUSIBLE).all())
        self._repeats_next = self.repeats + 1 if finite and np.array_equal(z, self.last_raw) else 0
        frozen = self.freeze_frames is not None and self._repeats_next >= self.freeze_frames
        valid = self._valid = finite and not frozen
        self._rejections_next = self.rejections
        self._post = None
        if not self.initialised:
            if valid:
                self._post = self._replay(k // self.every)
                self._write(self._post[0], predicted=False)
            else:
                self._write(np.full(self.order * self.n, np.nan), predicted=True)
            return

        x, p = self.x, self.P
        if frozen and self.has_shadow:
            # the run is confirmed frozen: rewind to the prediction that ignored its first copies
            x, p = self.shadow_x, self.shadow_P
        self._post = (x, p)
        if not valid:
            self._write(x, predicted=True)
            return
        kf = self._kf
        innovation = z - kf.H @ x
        nis = float(innovation @ np.linalg.solve(kf.H @ p @ kf.H.T + kf.R, innovation))
        if nis <= self.gate_threshold:
            kf.x, kf.P = x, p
            kf.update(z)
            self._post = (kf.x, kf.P)
            self._rejections_next = 0
        elif self.rejections + 1 >= self.max_rejections:
            self._post = self._replay(k // self.every)
            self._rejections_next = 0
        else:
            self._rejections_next = self.rejections + 1
            self._write(x, predicted=True)
            return
        self._write(self._post[0], predicted=False)

    def update(self, k: int) -> None:
        z = self._z
        # copies carry nothing new for a re-initialisation
        if self._valid and self._repeats_next == 0 and len(self.buf_n):
            self.buf_z = np.roll(self.buf_z, -1, axis=0)
            self.buf_z[-1] = z
            self.buf_n = np.roll(self.buf_n, -1)
            self.buf_n[-1] = k // self.every
            self.n_buf = min(self.n_buf + 1, len(self.buf_n))
        if self._finite:
            self.last_raw = z.copy()
            self.repeats = self._repeats_next
        self.rejections = self._rejections_next
        in_unconfirmed_run = (
            self.initialised and self.freeze_frames is not None and 0 < self.repeats < self.freeze_frames
        )
        if in_unconfirmed_run:
            base = (self.shadow_x, self.shadow_P) if self.has_shadow else (self.x, self.P)
            self.shadow_x, self.shadow_P = self._predict(*base)
        self.has_shadow = in_unconfirmed_run
        if self._post is not None:
            self.x, self.P = self._predict(*self._post)
            self.initialised = True

    # -- helpers ---------------------------------------------------------------
    def _predict(self, x: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        kf = self._kf
        kf.x, kf.P = x, p
        kf.predict()
        return kf.x, kf.P

    def _replay(self, n_now: int) -> tuple[np.ndarray, np.ndarray]:
        """Posterior at tick ``n_now`` from the prior at the oldest buffered sample, updated by the rest and ``z``.

        The buffer holds the last ``max_rejections - 1`` valid, non-repeated samples before
        this one: at a re-initialisation, the rejected measurements of the streak.
        """
        first = len(self.buf_n) - self.n_buf
        ticks = np.append(self.buf_n[first:], n_now)
        samples = np.vstack([self.buf_z[first:], self._z])
        kf = self._kf
        x = np.zeros(self.order * self.n)
        x[0 :: self.order] = samples[0]
        kf.x, kf.P = x, np.diag(self._prior_var)
        for step, z in zip(np.diff(ticks), samples[1:], strict=True):
            dt = step * self.dt
            kf.predict(
                F=self._transition(dt),
                Q=Q_continuous_white_noise(self.order, dt, self.process_noise, block_size=self.n),
            )
            kf.update(z)
        return kf.x, kf.P

    def _write(self, state: np.ndarray, *, predicted: bool) -> None:
        order, shape = self.order, self.p_hat.value.shape
        self.p_hat.value[...] = state[0::order].reshape(shape)
        self.v_hat.value[...] = state[1::order].reshape(shape)
        self.a_hat.value[...] = state[2::order].reshape(shape) if order == 3 else 0.0
        self.predicted.value[...] = predicted


def axis_transition(order: int, dt: float) -> np.ndarray:
    """One axis's state transition over ``dt`` s of the kinematic model of ``order`` states (position first)."""
    rows = range(order)
    return np.array([[dt ** (j - i) / math.factorial(j - i) if j >= i else 0.0 for j in rows] for i in rows])


def _shape_of(dims: int) -> tuple[int, ...]:
    return () if dims == 1 else (dims,)


def fit_noise(
    positions: Any,
    dt: float,
    model: str = "cv",
    *,
    max_lag: int = 16,
    robust: bool = True,
) -> dict[str, Any]:
    """Estimate the process and measurement noise of a recording for :class:`KalmanEstimator`.

    Method: for the order-m model (m = 2 for cv, 3 for ca) the m-th difference
    at lag L, ``Δ^m_L x[t] = Σ_j (-1)^(m-j) C(m, j) x[t + jL]``, of a sampled
    continuous white-noise kinematic process plus white measurement noise of
    variance r is zero-mean with variance

    ``V(L) = c_m q (L dt)^(2m-1) + C(2m, m) r``,  c_2 = 2/3, c_3 = 11/20

    (c_m is the squared norm of the B-spline kernel that the difference applies
    to the white acceleration or jerk). V(L) is measured at the lags
    ``L = 1, 2, 4, … <= max_lag``, pooling the axes, and ``(q, r) >= 0`` are
    fitted by non-negative least squares on relative errors. Measurement noise
    dominates at short lags, process noise at long ones, so the lags separate
    the two.

    Parameters
    ----------
    positions : array_like
        Samples, shape (T,) or (T, n); NaN frames are left out of every
        difference that touches them.
    dt : float
        Sampling step in seconds.
    model : {"cv", "ca"}
        The model whose parameters to fit.
    max_lag : int
        Longest lag in samples. On real motion, which is not white-noise driven,
        ``q`` is the equivalent intensity over the time scales up to
        ``max_lag * dt``: choose it near the horizon the filter must track.
    robust : bool
        Estimate each V(L) as ``median(d²) / 0.455`` (exact for Gaussian d)
        instead of ``mean(d²)``, so that spikes and frozen stretches barely move
        it, at the price of a larger spread (about 1.6 times the standard error).

    Returns
    -------
    dict
        ``{"model": model, "process_noise": q, "measurement_noise": sqrt(r)}``:
        keyword arguments for :class:`KalmanEstimator`.
    """
    model = one_of("fit_noise", "model", model, MODELS)
    dt = finite_number("fit_noise", "dt", dt, low=0.0, low_open=True)
    max_lag = positive_int("fit_noise", "max_lag", max_lag)
    try:
        x = np.array(positions, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"fit_noise: positions must be an array of numbers, got {positions!r}") from None
    if x.ndim == 1:
        x = x[:, None]
    if x.ndim != 2:
        raise ValueError(f"fit_noise: positions must have shape (T,) or (T, n), got {x.shape}")
    m = ORDER[model]
    binom = [math.comb(m, j) * (-1) ** (m - j) for j in range(m + 1)]
    lags = [2**i for i in range(int(math.log2(max_lag)) + 1)]
    if len(x) < m * lags[-1] + 20:
        raise ValueError(
            f"fit_noise: positions must hold at least {m * lags[-1] + 20} samples for max_lag={max_lag}, got {len(x)}"
        )
    variances = []
    for lag in lags:
        span = len(x) - m * lag
        d = sum(b * x[j * lag : j * lag + span] for j, b in enumerate(binom))
        d = d[np.isfinite(d)]
        if d.size < 10:
            raise ValueError(f"fit_noise: too few finite samples to form differences at lag {lag}")
        variances.append(np.median(d**2) / _CHI2_1_MEDIAN if robust else np.mean(d**2))
    v = np.array(variances)
    if not np.all(v > 0):
        raise ValueError("fit_noise: the positions do not vary; cannot estimate noise")
    design = np.column_stack(
        [
            _PROCESS_FACTOR[m] * (np.array(lags, dtype=float) * dt) ** (2 * m - 1),
            np.full(len(lags), float(math.comb(2 * m, m))),
        ]
    )
    weighted = design / v[:, None]
    scale = np.linalg.norm(weighted, axis=0)  # equalise the columns for the solver
    theta, _ = scipy.optimize.nnls(weighted / scale, np.ones(len(lags)))
    q, r = theta / scale
    return {"model": model, "process_noise": float(q), "measurement_noise": float(math.sqrt(r))}
