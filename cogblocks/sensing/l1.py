"""The L1 cognitive architecture: an avatar that replicates its participant's motion (section 4).

The L1 virtual human shows the participant's own motion, "compensating for
digital alterations such as delays and noise" (section 3). Its input is the
motion-capture stream as it arrives (late by the transport delay, noisy, with
dropouts); its output is the position the avatar shows now.

:class:`L1` is a :class:`~cogblocks.sim.Diagram` of two blocks, so either can be
swapped (``l1.replace("kalman", ...)``) or probed (``"l1.kalman.v_hat"``)::

    p ──┬─────────────────────────────┐
        └─> kalman (KalmanEstimator) ──> predictor (KinematicPredictor) ──> p_avatar
             p_hat, v_hat, a_hat, predicted"""

from __future__ import annotations

import numpy as np

from cogblocks.sensing.kalman import KalmanEstimator
from cogblocks.sim import Block, Diagram, Signal
from cogblocks.sim.params import finite_number, flag, unit_arg

__all__ = ["KinematicPredictor", "L1"]


class KinematicPredictor(Block):
    """Extrapolate a kinematic estimate ``horizon`` seconds ahead: ``p + v τ + ½ a τ²``.

    For the Kalman estimator's constant-velocity and constant-acceleration
    models this is exactly the model's own prediction ``F(τ) x`` (``a`` is zero
    for cv), so it needs no knowledge of the model.

    Ports
    -----
    p : input, positions as measured (scalar or vector, ``unit``)
    p_hat, v_hat, a_hat, predicted : inputs, the estimator's outputs
    p_out : output, spec of ``p``
        The extrapolated position.

    Parameters
    ----------
    horizon : float
        Seconds to predict ahead (>= 0).
    smoothing : bool
        Extrapolate from the estimate ``p_hat`` (True) or from the measurement
        ``p`` itself (False). In the second case frames the estimator flagged as
        ``predicted`` (missing, frozen or rejected samples) still use ``p_hat``,
        so bad samples never reach the output.
    unit : str
        Unit of the positions.

    Notes
    -----
    Bad data policy: with ``horizon = 0`` the velocity and acceleration are not
    used at all (so a non-finite one cannot reach the output); otherwise a
    non-finite estimate gives a non-finite output, as the estimator documents.
    """

    def __init__(
        self,
        horizon: float = 0.0,
        *,
        smoothing: bool = True,
        unit: str = "mm",
        period: float | None = None,
    ) -> None:
        super().__init__(period=period)
        self.horizon = finite_number(self, "horizon", horizon, low=0.0)
        self.smoothing = flag(self, "smoothing", smoothing)
        position = Signal(shape=None, unit=unit_arg(self, "unit", unit))
        self.add_input("p", position)
        self.add_input("p_hat", position)
        self.add_input("v_hat", position.with_(unit=f"{unit}/s"))
        self.add_input("a_hat", position.with_(unit=f"{unit}/s^2"))
        self.add_input("predicted", Signal(dtype=bool))
        self.add_output("p_out", like="p")

    def setup(self) -> None:
        shapes = {port.spec.shape for port in (self.p, self.p_hat, self.v_hat, self.a_hat)}
        if len(shapes) != 1:
            raise self._fail(f"p, p_hat, v_hat and a_hat must share one shape, got {sorted(shapes)}")

    @np.errstate(invalid="ignore", over="ignore")  # a non-finite estimate passes (documented), silently
    def output(self, k: int) -> None:
        base = self.p_hat.value if self.smoothing or self.predicted.value else self.p.value
        tau = self.horizon
        if tau == 0.0:  # nothing to extrapolate: do not touch v and a (0 * inf is NaN)
            self.p_out.value[...] = base
            return
        self.p_out.value[...] = base + tau * self.v_hat.value + (0.5 * tau * tau) * self.a_hat.value


class L1(Diagram):
    """L1 avatar: the participant's motion, cleaned of bad samples, smoothed and delay-compensated.

    Ports
    -----
    p : input, scalar or shape (n,), the estimator's unit
        Positions as they arrive: late by ``delay``, noisy, possibly NaN,
        frozen or spiky.
    p_avatar : output, spec of ``p``
        Position the avatar shows at this tick.

    Parameters
    ----------
    delay : float
        Known transport delay in seconds, compensated by predicting ahead with
        the estimator's kinematic model (``p + v·delay + ½ a·delay²``). 0 turns
        compensation off.
    smoothing : bool
        Show the Kalman estimate (True), or the measured position wherever the
        estimator accepted it (False; missing, frozen and rejected frames are
        still replaced by the estimate). With ``smoothing=False`` and
        ``delay=0`` the avatar passes every good sample through unchanged.
    estimator : KalmanEstimator, optional
        The estimator to use; by default ``KalmanEstimator("ca")`` in millimetres
        (a constant-acceleration model extrapolates oscillations much better
        than constant velocity; see docs/l1-and-sensor-streams.md).

    Notes
    -----
    Section 4 states that the current sensors (IMUs fused with cameras) need no
    signal compensation; this architecture covers the delays and noise that
    section 3 assigns to L1 for streams that do need it. Bad data policy: that of
    :class:`~cogblocks.sensing.KalmanEstimator`; the output is NaN
    only before the first sample the estimator can use (finite and below
    1e9: a larger value is a corrupted one, missing like NaN).
    """

    def __init__(
        self,
        delay: float = 0.0,
        *,
        smoothing: bool = True,
        estimator: KalmanEstimator | None = None,
        period: float | None = None,
    ) -> None:
        super().__init__(period=period)
        self.delay = finite_number(self, "delay", delay, low=0.0)
        smoothing = flag(self, "smoothing", smoothing)
        if estimator is None:
            estimator = KalmanEstimator("ca")
        elif not isinstance(estimator, KalmanEstimator):
            raise ValueError(f"L1: estimator must be a KalmanEstimator, got {type(estimator).__name__}")
        kalman = self.add("kalman", estimator)
        predictor = self.add("predictor", KinematicPredictor(self.delay, smoothing=smoothing, unit=estimator.unit))
        self.smoothing = predictor.smoothing
        self.connect(kalman.p_hat, predictor.p_hat)
        self.connect(kalman.v_hat, predictor.v_hat)
        self.connect(kalman.a_hat, predictor.a_hat)
        self.connect(kalman.predicted, predictor.predicted)
        self.expose_input("p", kalman.p, predictor.p)
        self.expose_output("p_avatar", predictor.p_out)
