"""The reference customizer of section 6: the reference cycle fitted to the last period (resample, scale, rotate)."""

from __future__ import annotations

from typing import Any

import numpy as np

from cogblocks.blocks.samples import plausible
from cogblocks.blocks.specs import COUNT
from cogblocks.sim import Block, Signal
from cogblocks.sim.params import finite_array, finite_number, one_of

__all__ = ["CUSTOMIZATIONS", "ReferenceCustomizer", "customize_reference", "kabsch_rotation"]

#: How the reference is fitted to a period: a least-squares linear map, or the deliverable's scale-then-rotate.
CUSTOMIZATIONS = ("affine", "deliverable")

# A degenerate reference axis: its spread is below this share of the largest spread.
_DEGENERATE = 1e-9


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
    """:func:`customize_reference` on checked arrays (the block calls this once per period)."""
    n, m = len(ref), len(per)
    at = np.arange(m) * (n / m)
    below = at.astype(np.intp)
    frac = (at - below)[:, None]
    resampled = ref[below] * (1.0 - frac) + ref[(below + 1) % n] * frac  # the curve is closed
    q = resampled - resampled.mean(axis=0)
    centroid = per.mean(axis=0)
    p = per - centroid
    if customization == "affine":
        a_t, *_ = np.linalg.lstsq(q, p, rcond=None)  # q @ a_t ≈ p
        positions = q @ a_t + centroid
    else:
        sd_ref, sd_per = q.std(axis=0), p.std(axis=0)
        moving = sd_ref > _DEGENERATE * max(float(sd_ref.max()), 1.0)
        scale = np.ones(3)
        scale[moving] = sd_per[moving] / sd_ref[moving]
        q *= scale
        positions = q @ kabsch_rotation(q, p).T + centroid
    velocities = (positions - np.roll(positions, 1, axis=0)) / dt
    return positions, velocities


class ReferenceCustomizer(Block):
    """Fit the reference motion to the last completed period (section 6.1.2 b).

    Runs :func:`customize_reference` each time a new period arrives (when ``period_count``
    changes) and holds the result in between.

    Ports
    -----
    last_period : input, shape (capacity, 3), mm
        The last completed period, in its first ``last_length`` rows.
    last_length, period_count : input, int64
        Its length and the period counter (see :class:`PeriodEstimator`).
    positions : output, shape (capacity, 3), mm
        The customised reference γ^c in its first ``length`` rows (zeros after them).
    velocities : output, shape (capacity, 3), mm/s
        Its backward-difference velocity, in the same rows.
    length : output, int64
        Number of samples of γ^c (the period's length ``M_ℓ``; 0 before the first period).
    count : output, int64
        The period counter γ^c was made from (0: no customised reference yet).

    Parameters
    ----------
    reference : array_like, shape (N, 3)
        The reference motion γ_ref, one cycle from phase 0, in mm (N >= 2).
    customization : {"affine", "deliverable"}
        How the reference is fitted, see :func:`customize_reference`.

    Notes
    -----
    Bad data policy: a period with a non-finite or implausible (beyond 1 km)
    coordinate is not fitted; the previous customised reference holds.
    """

    def __init__(self, reference: Any, *, customization: str = "affine", period: float | None = None) -> None:
        super().__init__(period=period)
        self.reference = _as_curve("ReferenceCustomizer", "reference", reference, 2)
        self.customization = one_of(self, "customization", customization, CUSTOMIZATIONS)
        self.add_input("last_period", Signal(shape=None, unit="mm"))
        self.add_input("last_length", COUNT)
        self.add_input("period_count", COUNT)
        self.add_output("positions", like="last_period")
        self.add_output("velocities", like="last_period", unit="mm/s")
        self.add_output("length", COUNT)
        self.add_output("count", COUNT)

    def setup(self) -> None:
        shape = self.last_period.spec.shape
        if len(shape) != 2 or shape[1] != 3 or shape[0] < 2:
            raise self._fail(f"last_period must have shape (capacity, 3) with capacity >= 2, got {shape}")

    def output(self, k: int) -> None:
        count = int(self.period_count.value)
        if count == self.count.value:
            return
        m = int(self.last_length.value)
        if m < 2 or not plausible(self.last_period.value[:m]):
            return
        positions, velocities = _customize(self.reference, self.last_period.value[:m], self.dt, self.customization)
        self.positions.value[:m] = positions
        self.positions.value[m:] = 0.0
        self.velocities.value[:m] = velocities
        self.velocities.value[m:] = 0.0
        self.length.value[...] = m
        self.count.value[...] = count
