"""The online 3D phase estimator of section 6: period estimator, reference customizer and phase computer."""

from __future__ import annotations

from typing import Any

from cogblocks.blocks.discrete import BackwardDifference
from cogblocks.phase.computer import PhaseComputer
from cogblocks.phase.customizer import ReferenceCustomizer, _as_curve
from cogblocks.phase.period import PeriodEstimator
from cogblocks.sensing import KalmanEstimator
from cogblocks.sim import Diagram
from cogblocks.sim.params import one_of

__all__ = ["PhaseEstimator3D"]


class PhaseEstimator3D(Diagram):
    """Online phase of a quasi-periodic 3D motion (section 6.1, Figure 11), as one block.

    A :class:`BackwardDifference` (named ``velocity``) gives the velocity from the positions, a
    :class:`PeriodEstimator` (``period``) records the last completed period, a
    :class:`ReferenceCustomizer` (``customizer``) fits the reference to it and a
    :class:`PhaseComputer` (``phase``) finds the phase on the fitted reference; the phase is fed
    back to the period estimator, which ends the later periods where it wraps. The velocity is
    computed inside, by the same backward difference as the reference's velocity, so that the two
    match in noise and lag; give a smoothed position if the sensor is noisy.

    With ``velocity="kalman"`` a :class:`~cogblocks.sensing.KalmanEstimator` named
    ``kalman`` (``kalman_model``, three axes, its defaults for arm motion in mm) replaces the
    backward difference: its ``p_hat`` goes to the period estimator and the phase computer in place
    of the raw position, its ``v_hat`` to the phase computer in place of the differences. It
    smooths the noise and predicts through missing and frozen samples.

    Ports
    -----
    p : input, shape (3,), mm (or any unit)
        Position of the tracked point.
    theta : output, rad, wrapped
        Estimated phase in ``[0, 2π)``, 0 at the start of the reference motion; held at 0 while
        ``valid`` is False.
    valid : output, bool
        False during the first period (and until its end has been detected), True after.

    Parameters
    ----------
    reference : array_like, shape (N, 3)
        The reference motion γ_ref, one cycle from phase 0, in mm.
    h, capacity, start_speed, match_ratio, min_period_fraction
        See :class:`PeriodEstimator`.
    search, window, jump_factor, distance_floor, velocity_weight, extrapolate, amplitude_range
        See :class:`PhaseComputer`; ``amplitude_range`` is 1.3 by default, 1 (the deliverable's
        distance) with ``customization="deliverable"``.
    velocity : {"difference", "kalman"}
        Backward differences of the raw position (default) or the Kalman front end above.
    kalman_model : {"cv", "ca"}
        Model of that Kalman filter (``"ca"`` by default); unused with ``velocity="difference"``.
    customization : {"affine", "deliverable"}
        The family of the map that fits the reference to each period (see
        :func:`customize_reference`): a least-squares linear map (default; any rotation and scale),
        or the deliverable's per-axis scale then rotation, for reproduction.
    grid : int, optional
        Phase grid of the customised reference (see :class:`ReferenceCustomizer`).

    Notes
    -----
    Units: every rule about time is given in seconds and converted with the step (``h``,
    ``window``, ``velocity_weight``), so that the estimator behaves the same at 30 and 240 Hz; every
    rule about amplitude is relative to the signal's own scale (``start_speed`` to the spread of the
    samples before the motion, ``distance_floor`` to the customised reference's spread), so that with
    ``velocity="difference"`` the same motion in mm, m or sensor counts gives the same phase. The
    reference may be in other units than the positions: the fitted map absorbs the scale. The Kalman
    front end's noise defaults are in mm (not unit-free). The phase is anchored to the reference's
    phase coordinate (see :func:`anchored_reference`).

    Bad data policy: a non-finite sample, or one beyond 1e100 (a corrupted number in any unit), gives a bad
    velocity inside, on which the period estimator skips the sample and the phase computer holds the phase; with
    ``velocity="kalman"`` the filter predicts through it instead. ``theta`` is never NaN.
    """

    def __init__(
        self,
        reference: Any,
        *,
        h: float = 0.1,
        capacity: int = 2400,
        start_speed: float = 1.0,
        match_ratio: float = 0.3,
        min_period_fraction: float = 0.7,
        search: str = "warm",
        window: float = 0.1,
        jump_factor: float = 3.0,
        distance_floor: float = 0.04,
        velocity_weight: float = 0.01,
        extrapolate: float = 0.5,
        amplitude_range: float | None = None,
        velocity: str = "difference",
        kalman_model: str = "ca",
        customization: str = "affine",
        grid: int | None = None,
        period: float | None = None,
    ) -> None:
        super().__init__(period=period)
        self.velocity = one_of(self, "velocity", velocity, ("difference", "kalman"))
        self.kalman_model = one_of(self, "kalman_model", kalman_model, ("cv", "ca"))
        reference = _as_curve("PhaseEstimator3D", "reference", reference, 2)
        if velocity == "kalman":
            front = self.add("kalman", KalmanEstimator(kalman_model, dims=3, unit="mm"))
        else:
            front = self.add("velocity", BackwardDifference())
        estimator = self.add(
            "period",
            PeriodEstimator(
                h=h,
                capacity=capacity,
                start_speed=start_speed,
                match_ratio=match_ratio,
                min_period_fraction=min_period_fraction,
            ),
        )
        customizer = self.add("customizer", ReferenceCustomizer(reference, customization=customization, grid=grid))
        phase = self.add(
            "phase",
            PhaseComputer(
                search=search,
                window=window,
                jump_factor=jump_factor,
                distance_floor=distance_floor,
                velocity_weight=velocity_weight,
                extrapolate=extrapolate,
                # the deliverable's distance with its customizer: the reproduction stays the deliverable's
                amplitude_range=(1.0 if customization == "deliverable" else 1.3)
                if amplitude_range is None
                else amplitude_range,
            ),
        )
        self.connect(estimator.last_period, customizer.last_period)
        self.connect(estimator.last_phases, customizer.last_phases)
        self.connect(estimator.last_length, customizer.last_length)
        self.connect(estimator.last_duration, customizer.last_duration)
        self.connect(estimator.period_count, customizer.period_count)
        self.connect(customizer.positions, phase.positions)
        self.connect(customizer.velocities, phase.velocities)
        self.connect(customizer.length, phase.length)
        self.connect(customizer.count, phase.count)
        self.connect(customizer.duration, phase.duration)
        self.connect(phase.theta, estimator.theta)
        self.connect(phase.valid, estimator.valid)
        if velocity == "kalman":
            self.connect(front.p_hat, estimator.p, phase.p)
            self.connect(front.v_hat, phase.v)
            self.expose_input("p", front.p)
        else:
            self.connect(front.y, phase.v)
            self.expose_input("p", front.u, estimator.p, phase.p)
        self.expose_output("theta", phase.theta)
        self.expose_output("valid", phase.valid)
