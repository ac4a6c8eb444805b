"""Offline phase references: the Hilbert phase of a 1D oscillation and the PCA-Hilbert phase of a 3D one."""

from __future__ import annotations

import math

import numpy as np
import scipy.signal
import scipy.stats

from cogblocks.blocks.angles import TWO_PI, wrap_2pi
from cogblocks.phase.customizer import _as_curve
from cogblocks.sim.params import finite_number
from cogblocks.sim.timing import BASE_STEP

__all__ = ["hilbert_phase", "mean_cycle", "offline_phase_pca_hilbert"]


def hilbert_phase(p: np.ndarray, *, dt: float = BASE_STEP, highpass: float | None = None) -> np.ndarray:
    """Offline phase of a 1D oscillation: the angle of the analytic signal of the centred position.

    Same convention as :class:`PhaseEstimator`: ``p = cos ωt`` gives ``θ = ωt`` (the analytic signal
    of ``cos ωt`` is ``exp(iωt)``).

    Parameters
    ----------
    p : array_like, shape (n,)
        Positions sampled every ``dt``; finite values only.
    dt : float
        Sampling time in seconds (used only with ``highpass``).
    highpass : float, optional
        Centre with a zero-phase (forward-backward) second-order Butterworth high-pass at this
        cut-off in Hz instead of subtracting the mean: it also removes a slowly drifting offset.

    Returns
    -------
    numpy.ndarray
        Phases in ``[0, 2π)``, shape (n,). Like every Hilbert phase it is unreliable within about
        one period of either end.
    """
    x = np.asarray(p, dtype=np.float64)
    if x.ndim != 1 or len(x) < 2:
        raise ValueError(f"hilbert_phase: p must be a 1-D array of at least 2 samples, got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError(f"hilbert_phase: p must be finite; it has {int(np.sum(~np.isfinite(x)))} NaN/inf sample(s)")
    dt = finite_number("hilbert_phase", "dt", dt, low=0.0, low_open=True)
    if highpass is None:
        x = x - x.mean()
    else:
        highpass = finite_number(
            "hilbert_phase", "highpass", highpass, low=0.0, high=0.5 / dt, low_open=True, high_open=True
        )
        sos = scipy.signal.butter(2, highpass, btype="highpass", fs=1.0 / dt, output="sos")
        x = scipy.signal.sosfiltfilt(sos, x)
    theta = wrap_2pi(np.angle(scipy.signal.hilbert(x)))
    return theta


# Offline phase: share of a cycle skipped at the start of a record when measuring the first cycle,
# and the number of passes of the Hilbert transform with periodic padding.
_EDGE_SHARE = 0.05
_PADDED_PASSES = 2
_PAD_CYCLES = 3


def offline_phase_pca_hilbert(positions: np.ndarray, *, anchor: bool = True) -> np.ndarray:
    """Offline phase of a recorded 3D motion: PCA, then the Hilbert phase (section 6.1.3).

    The centred positions are projected on their first principal direction and the phase is the
    unwrapped angle of the analytic signal (``scipy.signal.hilbert``) of that projection.

    *Edge effects.* The FFT behind the Hilbert transform treats the record as periodic, so the
    jump between its last and first samples distorts the phase near both ends (the first sample
    can be off by radians, the next tens of samples by tenths of a radian). The projection is
    therefore extended by three cycles at each end, periodically (the first cycle repeated before
    the start, the last after the end), before the transform. The cycle length comes from the
    previous pass: the (interpolated) number of samples the phase takes to gain 2π, counted from
    5 % of a cycle in; two padded passes follow one plain pass.

    *Alignment.* The phase increases with time whatever the sign of the principal direction; the
    sign (fixed so that the direction's largest component is positive) and the Hilbert convention
    (phase 0 at a maximum of the projection) only shift it by a constant. That constant is set to
    the online convention, phase 0 at the start of the motion and one turn per cycle (assumption 3
    of section 6.1.1): over the first cycle, of ``K`` samples (``K`` fractional), the circular mean
    of ``2π k / K − φ(k)`` is removed. Averaging over a whole cycle cancels the noise and most of the
    ripple the Hilbert phase has within a cycle of a non-sinusoidal motion.

    Parameters
    ----------
    positions : numpy.ndarray, shape (n, 3)
        The whole recording in mm, at a constant sampling rate; at least one full cycle.
    anchor : bool
        Set phase 0 at the start of the motion as above (default). False keeps the Hilbert
        convention, phase 0 at each maximum of the projection on the principal direction: a
        landmark of the movement itself, the same for people making the same movement in the same
        frame, so that their phases can be compared (a group's order parameter).

    Returns
    -------
    numpy.ndarray, shape (n,)
        Phase in rad, wrapped to ``[0, 2π)``.

    Raises
    ------
    ValueError
        If the positions are not an (n, 3) array of finite numbers, or hold less than one cycle.
    """
    owner = "offline_phase_pca_hilbert"
    x = _as_curve(owner, "positions", positions, 4)
    centred = x - x.mean(axis=0)
    direction = np.linalg.svd(centred, full_matrices=False)[2][0]
    direction *= np.sign(direction[np.argmax(np.abs(direction))])
    signal = centred @ direction
    phase = np.unwrap(np.angle(scipy.signal.hilbert(signal)))
    for _ in range(_PADDED_PASSES):
        cycle = _first_cycle(phase, owner)
        # a mean over a whole number of cycles: a partial cycle leaves an offset that ripples the phase
        signal = signal - signal[: round(len(signal) // cycle * cycle)].mean()
        c = round(cycle)
        pad = _PAD_CYCLES * c
        padded = np.concatenate([np.tile(signal[:c], _PAD_CYCLES), signal, np.tile(signal[-c:], _PAD_CYCLES)])
        phase = np.unwrap(np.angle(scipy.signal.hilbert(padded)))[pad : pad + len(signal)]
    if not anchor:
        return wrap_2pi(phase)
    cycle = _first_cycle(phase, owner)
    k = np.arange(round(cycle))
    offset = scipy.stats.circmean(TWO_PI * k / cycle - phase[k], high=np.pi, low=-np.pi)
    return wrap_2pi(phase + offset)


def mean_cycle(positions: np.ndarray, n_samples: int = 200, *, anchor: bool = True) -> np.ndarray:
    """A reference motion made from a recording: its mean cycle over its offline phase.

    Samples are binned by their :func:`offline_phase_pca_hilbert` phase into ``n_samples`` equal bins
    and averaged; a bin no sample fell in is interpolated from its neighbours (circularly). Phase 0
    is the offline phase's: the start of the motion, as the online estimator counts it, or with
    ``anchor=False`` the maximum of the projection (see :func:`offline_phase_pca_hilbert`). For a
    recording without a primitive library, this is the ``reference`` of
    :class:`~cogblocks.phase.PhaseEstimator3D`.

    Parameters
    ----------
    positions : numpy.ndarray, shape (n, 3)
        The recording at a constant rate, finite, at least one full cycle.
    n_samples : int
        Samples of the returned cycle (>= 3).
    anchor : bool
        Passed to :func:`offline_phase_pca_hilbert`.

    Returns
    -------
    numpy.ndarray, shape (n_samples, 3)
        The cycle at the phases ``2π i / n_samples``, in the positions' unit.
    """
    x = _as_curve("mean_cycle", "positions", positions, 4)
    if not (isinstance(n_samples, int) and n_samples >= 3):
        raise ValueError(f"mean_cycle: n_samples must be an integer >= 3, got {n_samples!r}")
    bins = np.minimum((offline_phase_pca_hilbert(x, anchor=anchor) / TWO_PI * n_samples).astype(int), n_samples - 1)
    counts = np.bincount(bins, minlength=n_samples)
    sums = np.stack([np.bincount(bins, weights=x[:, axis], minlength=n_samples) for axis in range(3)], axis=1)
    filled = counts > 0
    centres = np.arange(n_samples)
    cycle = sums[filled] / counts[filled, None]
    return np.stack(
        [np.interp(centres, centres[filled], cycle[:, axis], period=n_samples) for axis in range(3)], axis=1
    )


def _first_cycle(phase: np.ndarray, owner: str) -> float:
    """Samples (interpolated) the unwrapped phase takes to gain 2π, from 5 % of a median cycle in."""
    step = float(np.median(np.diff(phase)))
    skip = math.ceil(_EDGE_SHARE * TWO_PI / step) if step > 0.0 else 0
    gained = phase[skip:] - phase[min(skip, len(phase) - 1)]
    past = np.flatnonzero(gained >= TWO_PI)
    if step <= 0.0 or past.size == 0:
        raise ValueError(
            f"{owner}: positions must hold at least one full cycle of the motion, got {len(phase)} samples"
        )
    j = int(past[0])  # >= 1, since gained[0] = 0
    return j - 1 + (TWO_PI - gained[j - 1]) / (gained[j] - gained[j - 1])
