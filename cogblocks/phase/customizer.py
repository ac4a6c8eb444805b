"""The reference customizer of section 6: the reference cycle fitted to the last period (resample, scale, rotate)."""

from __future__ import annotations

from typing import Any

import numpy as np

from cogblocks.blocks.angles import TWO_PI
from cogblocks.blocks.samples import MEASURABLE, PLAUSIBLE, plausible
from cogblocks.blocks.specs import COUNT
from cogblocks.sim import Block, Signal
from cogblocks.sim.params import finite_array, finite_number, one_of, positive_int

__all__ = ["CUSTOMIZATIONS", "ReferenceCustomizer", "anchored_reference", "customize_reference", "kabsch_rotation"]

#: How the reference is fitted to a period: a least-squares linear map, or the deliverable's scale-then-rotate.
CUSTOMIZATIONS = ("affine", "deliverable")

# A degenerate reference axis: its spread is below this share of the largest spread.
_DEGENERATE = 1e-9
# The anchored fit: geometric re-estimations of the phases (first period, later ones), samples used, rows of
# the nearest-point search. The first period's phases are even in time, off by up to ±0.2 rad under a ±20 %
# speed variation; each re-estimation removes about 13 % of that, and Aitken's extrapolation every second one
# the most of what is left (10 with it come closer to the fixed point than 24 without). Later periods start
# from measured phases.
_FIRST_ITERATIONS = 10
_ITERATIONS = 4
_FIT_SAMPLES = 120  # the harder set: the same errors as with 200 (mean 0.0173 rad, p95 0.046), 40 % less work
_FIT_GRID = 128
# The re-estimations stop when they move the phases by less than this on average (rad): a tenth of the smallest
# error the later periods are still removing (0.003 rad on clean data); the grid step is 0.05.
_TOLERANCE = 1e-4
# Aitken's extrapolation is used when successive moves shrink by a ratio in (0, this).
_MAX_RATE = 0.95


def _as_curve(owner: str, name: str, value: Any, minimum: int) -> np.ndarray:
    arr = finite_array(owner, name, value, shape=(None, 3))
    if len(arr) < minimum:
        raise ValueError(f"{owner}: {name} must have at least {minimum} samples, got {len(arr)}")
    return arr


def kabsch_rotation(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The proper rotation that best maps centred points ``source`` onto ``target`` (Arun et al. 1987).

    Minimises ``Σ_i ‖R q_i − p_i‖²`` over rotations with ``det R = +1``: with the cross-covariance
    ``H = Σ_i q_i p_iᵀ = U Σ Vᵀ``, ``R = V Uᵀ``, and the last column of ``V`` is negated when that
    would be a reflection (``det < 0``), which gives the best proper rotation instead.

    Parameters
    ----------
    source, target : numpy.ndarray, shape (n, 3)
        Corresponding points ``q_i`` and ``p_i``, both already centred.

    Returns
    -------
    numpy.ndarray, shape (3, 3)
        ``R``, to be applied as ``R @ q`` (or ``source @ R.T``).
    """
    u, _, vt = np.linalg.svd(source.T @ target)
    v = vt.T
    if np.linalg.det(v @ u.T) < 0.0:
        v[:, -1] = -v[:, -1]
    return v @ u.T


def customize_reference(
    reference: Any, period: Any, dt: float = 1.0, *, customization: str = "affine"
) -> tuple[np.ndarray, np.ndarray]:
    """Fit the reference motion to one recorded period: the customised reference γ^c (section 6.1.2 b).

    1. Resample the closed reference curve to the period's number of samples ``M`` by linear
       interpolation (sample ``j`` sits at phase ``2π j / M``).
    2. Centre both curves.
    3. ``customization="affine"`` (default): map the reference by the linear map ``A`` that best
       fits the period sample by sample, ``min_A Σ_j ‖A q_j − p_j‖²`` (least squares; minimum norm
       along an axis the reference does not move along). Any rotation (0-180°) and any scale, per
       axis of the reference or of the world, is recovered exactly.
       ``customization="deliverable"``: scale the reference along each world axis by
       ``σ(period) / σ(reference)`` (an axis along which the reference does not move keeps a
       factor of 1), then rotate it by the proper rotation of :func:`kabsch_rotation`. The
       spreads are compared before the rotation is found, which distorts the fit under large
       rotations; kept for reproduction.
    4. Move it to the period's centroid.

    Velocities are backward differences along the closed curve (the first sample's predecessor is
    the last), divided by ``dt``.

    Parameters
    ----------
    reference : array_like, shape (N, 3)
        The reference motion γ_ref, one cycle from phase 0, in mm (N >= 2).
    period : array_like, shape (M, 3)
        The recorded period γ_ℓ in mm (M >= 2).
    dt : float
        Sampling time of the period in s (> 0); ``1`` gives velocities in mm per sample.
    customization : {"affine", "deliverable"}
        How the reference is fitted (step 3).

    Returns
    -------
    positions : numpy.ndarray, shape (M, 3)
        γ^c in mm.
    velocities : numpy.ndarray, shape (M, 3)
        Its backward-difference velocity in mm/s (mm per sample for ``dt = 1``).

    Examples
    --------
    >>> phi = 2 * np.pi * np.arange(100) / 100
    >>> ref = np.stack([np.cos(phi), np.sin(phi), 0 * phi], axis=1)
    >>> pos, vel = customize_reference(ref, 10 * ref[::2] + 5)
    >>> bool(np.allclose(pos, 10 * ref[::2] + 5))
    True
    """
    owner = "customize_reference"
    ref = _as_curve(owner, "reference", reference, 2)
    per = _as_curve(owner, "period", period, 2)
    dt = finite_number(owner, "dt", dt, low=0.0, low_open=True)
    return _customize(ref, per, dt, one_of(owner, "customization", customization, CUSTOMIZATIONS))


def _customize(ref: np.ndarray, per: np.ndarray, dt: float, customization: str) -> tuple[np.ndarray, np.ndarray]:
    """:func:`customize_reference` on checked arrays."""
    q = _on_curve(ref, TWO_PI * np.arange(len(per)) / len(per))
    a_t, c = _fit_map(q, per, customization)
    positions = q @ a_t + c
    velocities = (positions - np.roll(positions, 1, axis=0)) / dt
    return positions, velocities


def _on_curve(ref: np.ndarray, phases: np.ndarray) -> np.ndarray:
    """The closed curve ``ref`` (sample ``i`` at phase ``2π i / N``) at any phases, linearly interpolated."""
    n = len(ref)
    at = np.mod(phases, TWO_PI) * (n / TWO_PI)
    below = np.minimum(at.astype(np.intp), n - 1)
    frac = (at - below)[:, None]
    return ref[below] * (1.0 - frac) + ref[(below + 1) % n] * frac


def _fit_map(q: np.ndarray, per: np.ndarray, customization: str) -> tuple[np.ndarray, np.ndarray]:
    """The map ``x ↦ x @ a_t + c`` that fits reference points ``q`` to the corresponding ``per`` (step 2-4)."""
    q_mean, centroid = q.mean(axis=0), per.mean(axis=0)
    q, p = q - q_mean, per - centroid
    if customization == "affine":
        a_t, *_ = np.linalg.lstsq(q, p, rcond=None)  # q @ a_t ≈ p
    else:
        sd_ref, sd_per = q.std(axis=0), p.std(axis=0)
        moving = sd_ref > _DEGENERATE * float(sd_ref.max())  # relative: the same in any unit
        scale = np.ones(3)
        scale[moving] = sd_per[moving] / sd_ref[moving]
        a_t = scale[:, None] * kabsch_rotation(q * scale, p).T
    return a_t, centroid - q_mean @ a_t


def _nearest_phases(curve: np.ndarray, points: np.ndarray, guess: np.ndarray, reach: int) -> np.ndarray:
    """Phase of the nearest point of the closed ``curve`` to each point, within ``reach`` rows of ``guess``.

    The search is restricted around the guess so that a curve passing near itself cannot send a
    point to the other branch; the phase is refined between grid points by a parabola.
    """
    g = len(curve)
    reach = max(1, min(reach, g // 2 - 1))  # at least the two neighbours the parabola needs, rows counted once
    centre = np.rint(np.mod(guess, TWO_PI) * (g / TWO_PI)).astype(np.intp)
    rows = (centre[:, None] + np.arange(-reach, reach + 1)) % g  # the window of each point
    d2 = ((points[:, None, :] - curve[rows]) ** 2).sum(axis=2)
    j = np.clip(np.argmin(d2, axis=1), 1, 2 * reach - 1)  # the parabola needs both neighbours
    at = np.arange(len(points))
    before, here, after = d2[at, j - 1], d2[at, j], d2[at, j + 1]
    curvature = before - 2.0 * here + after
    with np.errstate(invalid="ignore", divide="ignore"):
        delta = np.where(curvature > 0.0, 0.5 * (before - after) / curvature, 0.0)
    return TWO_PI * (rows[at, j] + np.clip(delta, -0.5, 0.5)) / g


def anchored_reference(
    reference: Any,
    period: Any,
    phases: Any,
    *,
    customization: str = "affine",
    anchor: str = "mean",
    iterations: int = _ITERATIONS,
) -> tuple[np.ndarray, np.ndarray]:
    """Fit the reference to a period whose samples carry phases, keeping the phase coordinate anchored.

    The map of step 3 of :func:`customize_reference` is fitted on the pairs ``(γ_ref(φ_j), p_j)``,
    ``φ_j`` the phase of sample ``j``, rather than on the reference resampled to the period's sample
    count, so that neither a speed that varies within the cycle nor a frozen stretch distorts it.
    The phases are then re-estimated geometrically, as the nearest point of each sample on the
    fitted curve (which does not depend on the speed), and the fit repeated up to ``iterations``
    times: it stops when the phases move by less than 1e-4 rad on average; with ``anchor="start"``
    every second move is extrapolated by Aitken's rule (the moves shrink geometrically).
    A linear map can mimic a constant phase shift of an elliptic curve, so the geometry does not fix
    the phase origin: ``anchor`` does. ``"start"`` keeps the phase of the period's first sample
    (the start of the motion, phase 0 by assumption 3); ``"mean"`` keeps the given phases on
    average (they were measured on the previous, anchored reference), up to the part of a constant
    shift the map cannot mimic, which it removes: an error of the given phases is kept or reduced.

    Parameters
    ----------
    reference : array_like, shape (N, 3)
        The reference motion γ_ref, sample ``i`` at phase ``2π i / N``, in mm (N >= 2).
    period : array_like, shape (M, 3)
        Samples of one (or more) cycles in mm, M >= 4.
    phases : array_like, shape (M,)
        Their phases in rad (any unwrapping).
    customization : {"affine", "deliverable"}
        The family of the map (see :func:`customize_reference`).
    anchor : {"start", "mean"}
        What fixes the phase origin.
    iterations : int
        Most geometric re-estimations of the phases (>= 0).

    Returns
    -------
    a_t : numpy.ndarray, shape (3, 3)
        The linear part, applied as ``x @ a_t``.
    c : numpy.ndarray, shape (3,)
        The translation: ``γ^c(φ) = γ_ref(φ) @ a_t + c``.
    """
    owner = "anchored_reference"
    reference = _as_curve(owner, "reference", reference, 2)
    period = _as_curve(owner, "period", period, 4)
    phases = finite_array(owner, "phases", phases, shape=(len(period),))
    customization = one_of(owner, "customization", customization, CUSTOMIZATIONS)
    anchor = one_of(owner, "anchor", anchor, ("start", "mean"))
    iterations = positive_int(owner, "iterations", iterations, minimum=0)
    return _anchored_map(reference, period, phases, customization, anchor, iterations)


def _anchored_map(
    reference: np.ndarray, period: np.ndarray, phases: np.ndarray, customization: str, anchor: str, iterations: int
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`anchored_reference` on checked arrays (the block calls this once per period)."""
    if len(period) > _FIT_SAMPLES:  # a hundred samples fix twelve numbers; keep the fit cheap
        keep = np.linspace(0, len(period) - 1, _FIT_SAMPLES).round().astype(np.intp)
        period, phases = period[keep], phases[keep]
    g = min(len(reference), _FIT_GRID)
    coarse = _on_curve(reference, TWO_PI * np.arange(g) / g)  # nearest points are searched on g rows
    # "start": the first sample, where the motion began (phase 0, assumption 3); "mean": all of them
    anchored = np.arange(len(phases)) == 0 if anchor == "start" else np.ones(len(phases), dtype=bool)
    tags, previous = phases, None
    accelerate = anchor == "start"  # the first period's even-time phases converge slowly; later ones start close
    reach = g // 6  # the given phases may be off by a sixth of a cycle (the first period's by 0.3 rad)
    for _ in range(iterations):
        a_t, c = _fit_map(_on_curve(reference, tags), period, customization)
        found = _nearest_phases(coarse @ a_t + c, period, tags, reach)
        offset = np.angle(np.exp(1j * (found - phases)[anchored]).mean())
        step = (found - offset - tags + np.pi) % TWO_PI - np.pi  # the re-estimation's move, unwrapped
        tags = tags + step
        if float(np.abs(step).mean()) < _TOLERANCE:  # converged: a further re-estimation would move them less
            break
        # Aitken's extrapolation: the moves shrink geometrically (by a factor r, about 0.87 on the first
        # period), so the fixed point lies r / (1 - r) moves ahead; every second move, r estimated afresh
        rate = float(step @ previous / (previous @ previous)) if previous is not None else 0.0
        if accelerate and 0.0 < rate < _MAX_RATE:
            tags = tags + step * (rate / (1.0 - rate))
        previous = step if previous is None else None
        # each later re-estimation moves a phase by a row or two (0.1 rad at most on the harder set)
        reach = max(2, g // 32)
    return _fit_map(_on_curve(reference, tags), period, customization)


class ReferenceCustomizer(Block):
    """Fit the reference motion to the last completed period (section 6.1.2 b), on a fixed phase grid.

    Each time a new period arrives (when ``period_count`` changes) the map of
    :func:`anchored_reference` is fitted on the period's samples and their phases, and the
    customised reference is that map applied to γ_ref at the phases ``2π g / G``,
    ``g = 0 … G − 1``: its phase coordinate is the reference's own, whatever the number of samples
    the period had (a real number) and however unevenly they were spread in phase. The first
    period is anchored at its start (phase 0, assumption 3), each later one to the phases measured
    on the previous customised reference, so the phase origin does not move from cycle to cycle.
    The result is held in between.

    The velocity of grid point ``g`` is the backward difference the sensor would see at the
    period's mean speed: ``(γ^c(φ_g) − γ^c(φ_g − 2π dt / T)) / dt``, ``T`` the period's duration.

    Ports
    -----
    last_period : input, shape (capacity, 3), mm
        The samples of the last completed period, in its first ``last_length`` rows.
    last_phases : input, shape (capacity,), rad
        Their phases.
    last_length, period_count : input, int64
        The number of samples and the period counter (see :class:`PeriodEstimator`).
    last_duration : input, s
        The period's duration.
    positions : output, shape (G, 3), mm
        The customised reference γ^c on the phase grid.
    velocities : output, shape (G, 3), mm/s
        Its velocity, as above.
    length : output, int64
        ``G`` once a reference has been fitted, 0 before.
    duration : output, s
        The duration of the period it was fitted to (0 before).
    count : output, int64
        The period counter γ^c was made from (0: no customised reference yet).

    Parameters
    ----------
    reference : array_like, shape (N, 3)
        The reference motion γ_ref, one cycle from phase 0, in mm (N >= 2).
    customization : {"affine", "deliverable"}
        ``"affine"``: the anchored fit above. ``"deliverable"``: the deliverable as it is, for
        reproduction: its scale-then-rotate fit (:func:`customize_reference`) with sample ``j`` of
        the period at phase ``2π j / M`` (phase 0 where the period began, the phases given are not
        used), held on the same grid; its phase is not anchored.
    grid : int, optional
        Phase grid size ``G`` (>= 8); N by default.

    Notes
    -----
    Bad data policy: a period with fewer than 4 samples, a non-finite coordinate or phase, or one beyond
    1e100 (a corrupted number in any unit), or a duration that is not a positive finite number is not fitted; the
    previous customised reference holds.
    """

    def __init__(
        self,
        reference: Any,
        *,
        customization: str = "affine",
        grid: int | None = None,
        period: float | None = None,
    ) -> None:
        super().__init__(period=period)
        self.reference = _as_curve("ReferenceCustomizer", "reference", reference, 2)
        self.customization = one_of(self, "customization", customization, CUSTOMIZATIONS)
        self.grid = len(self.reference) if grid is None else positive_int(self, "grid", grid, minimum=8)
        self._phases = TWO_PI * np.arange(self.grid) / self.grid
        self._curve = _on_curve(self.reference, self._phases)
        self.add_input("last_period", Signal(shape=None, unit="mm"))
        self.add_input("last_phases", Signal(shape=None, unit="rad"))
        self.add_input("last_length", COUNT)
        self.add_input("last_duration", Signal(shape=(), unit="s"))
        self.add_input("period_count", COUNT)
        self.add_output("positions", shape=(self.grid, 3), unit="mm")
        self.add_output("velocities", shape=(self.grid, 3), unit="mm/s")
        self.add_output("length", COUNT)
        self.add_output("duration", shape=(), unit="s")
        self.add_output("count", COUNT)

    def setup(self) -> None:
        shape = self.last_period.spec.shape
        if len(shape) != 2 or shape[1] != 3 or shape[0] < 4:
            raise self._fail(f"last_period must have shape (capacity, 3) with capacity >= 4, got {shape}")
        if self.last_phases.spec.shape != shape[:1]:
            raise self._fail(f"last_phases must have shape ({shape[0]},), got {self.last_phases.spec.shape}")

    def output(self, k: int) -> None:
        count = int(self.period_count.value)
        if count == self.count.value:
            return
        m = int(self.last_length.value)
        duration = float(self.last_duration.value)
        period, phases = self.last_period.value[:m], self.last_phases.value[:m]
        usable = plausible(period, MEASURABLE) and plausible(phases, MEASURABLE)
        if m < 4 or not (usable and 0.0 < duration < PLAUSIBLE):
            return
        if self.customization == "deliverable":
            # the deliverable as it is: sample j of the period at phase 2π j / M, phase 0 where the period began
            a_t, c = _fit_map(_on_curve(self.reference, TWO_PI * np.arange(m) / m), period, "deliverable")
        else:
            anchor = "start" if self.count.value == 0 else "mean"
            iterations = _FIRST_ITERATIONS if anchor == "start" else _ITERATIONS
            a_t, c = _anchored_map(self.reference, period, phases, self.customization, anchor, iterations)
        positions = self._curve @ a_t + c
        behind = _on_curve(self.reference, self._phases - TWO_PI * self.dt / duration) @ a_t + c
        self.positions.value[...] = positions
        self.velocities.value[...] = (positions - behind) / self.dt
        self.length.value[...] = self.grid
        self.duration.value[...] = duration
        self.count.value[...] = count
