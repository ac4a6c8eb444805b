"""The 3D phase chain on a recorded marker: a C3D or XDF file in place of the synthetic trajectories.

:func:`recorded_motion` reads one marker of a recording onto the 10 ms tick grid (gaps NaN, which
the online estimator holds through) and makes its reference motion from the recording itself
(:func:`~cogblocks.phase.mean_cycle`), since a lab's recording comes without the primitive library.
:func:`phase3d_recording` runs the online :class:`~cogblocks.phase.PhaseEstimator3D` on it, compares
it with the offline PCA-Hilbert phase, and runs the phase chain (:func:`~cogblocks.diagrams.phase3d.phase_chain`)
with the recorded person as the assisted participant: what ``cogblocks run phase3d --recording``
prints.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from cogblocks.blocks.angles import wrap_pi
from cogblocks.data.markers import MarkerRecording
from cogblocks.data.recordings import load_recording
from cogblocks.diagrams.phase3d import chain_summary, run_phase_estimator
from cogblocks.phase import mean_cycle, offline_phase_pca_hilbert
from cogblocks.sim.timing import BASE_STEP

__all__ = ["RecordedMotion", "filled", "phase3d_recording", "plot_phase3d_recording", "recorded_motion"]


@dataclass(frozen=True)
class RecordedMotion:
    """One recorded marker on the tick grid, with the reference made from it.

    Attributes
    ----------
    t : numpy.ndarray, shape (n,)
        Times in s, ``t[0] + k dt``.
    position : numpy.ndarray, shape (n, 3)
        Positions in mm, NaN where the marker was not seen.
    reference : numpy.ndarray, shape (200, 3)
        The recording's mean cycle (:func:`~cogblocks.phase.mean_cycle`), in mm.
    dt : float
        Tick in s.
    marker, source : str
        The marker's name and the file.
    """

    t: np.ndarray
    position: np.ndarray
    reference: np.ndarray
    dt: float
    marker: str
    source: str


def filled(position: np.ndarray) -> np.ndarray:
    """``position`` with its gaps bridged linearly (ends held), for the offline references only."""
    out = np.array(position, dtype=np.float64)
    seen = np.isfinite(out).all(axis=1)
    if seen.sum() < 2:
        raise ValueError("a marker must be seen on at least 2 samples")
    k = np.arange(len(out))
    for axis in range(out.shape[1]):
        out[:, axis] = np.interp(k, k[seen], out[seen, axis])
    return out


def recorded_motion(
    recording: str | os.PathLike | MarkerRecording, marker: str, *, dt: float = BASE_STEP
) -> RecordedMotion:
    """One marker of a C3D/XDF file (or of a loaded :class:`MarkerRecording`) on a grid of step ``dt``."""
    if isinstance(recording, MarkerRecording):
        rec = recording.select([marker]).resampled(dt)
    else:
        rec = load_recording(recording, [marker], dt=dt)
    position = rec.points[:, 0]
    try:
        reference = mean_cycle(filled(position))
    except ValueError as error:
        raise ValueError(f"{rec.source}: marker {rec.markers[0]!r}: {error}") from None
    return RecordedMotion(rec.t - rec.t[0], position, reference, dt, rec.markers[0], rec.source)


def phase3d_recording(
    recording: str | os.PathLike | MarkerRecording,
    marker: str,
    *,
    dt: float = BASE_STEP,
    motion_computer: str = "mean",
) -> dict[str, Any]:
    """The online 3D phase of a recorded marker against its offline PCA-Hilbert phase, and the phase chain on it.

    Returns
    -------
    dict
        ``file``, ``marker``, ``duration_s``, ``dt``, ``gap_share`` (share of ticks without the
        marker), ``valid_share`` (ticks with a valid online estimate), ``mean_error_vs_offline_rad``
        and ``p95_error_vs_offline_rad`` (``|wrap_π(online − offline)|`` on valid ticks the marker
        was seen) and ``chain`` (:func:`~cogblocks.diagrams.phase3d.chain_summary`).
    """
    motion = recorded_motion(recording, marker, dt=dt)
    run = run_phase_estimator(motion)
    seen = np.isfinite(motion.position).all(axis=1)
    offline = offline_phase_pca_hilbert(filled(motion.position))
    compared = run["valid"] & seen
    if not compared.any():
        raise ValueError(f"{motion.source}: marker {marker!r}: the online estimator found no complete period")
    error = np.abs(wrap_pi(run["theta"][compared] - offline[compared]))
    return {
        "file": motion.source,
        "marker": motion.marker,
        "duration_s": float(motion.t[-1] + dt),
        "dt": dt,
        "gap_share": float(1.0 - seen.mean()),
        "valid_share": float(run["valid"].mean()),
        "mean_error_vs_offline_rad": float(error.mean()),
        "p95_error_vs_offline_rad": float(np.percentile(error, 95)),
        "chain": chain_summary(motion, motion_computer),
    }


def plot_phase3d_recording(
    recording: str | os.PathLike | MarkerRecording,
    marker: str,
    path: str,
    *,
    dt: float = BASE_STEP,
    shown: float = 12.0,
) -> None:
    """Draw a recorded marker's online and offline phases (first ``shown`` s) and their difference to ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cogblocks.diagrams.phase3d import _break_wraps

    motion = recorded_motion(recording, marker, dt=dt)
    run = run_phase_estimator(motion)
    offline = offline_phase_pca_hilbert(filled(motion.position))
    seen = np.isfinite(motion.position).all(axis=1)
    valid = run["valid"] & seen
    t = motion.t
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 3.8))
    window = t < shown
    left.plot(t[window], _break_wraps(offline[window]), lw=1.2, label="offline (PCA + Hilbert)")
    left.plot(t[window], _break_wraps(np.where(valid, run["theta"], np.nan)[window]), lw=1.2, ls="--", label="online")
    for start in t[window][np.flatnonzero(np.diff(np.r_[1, seen[window].astype(int)]) == -1)]:
        left.axvline(start, color="0.7", lw=0.6)  # where the marker was lost
    left.set_xlabel("t [s]")
    left.set_ylabel("phase [rad]")
    left.set_title(f"{motion.marker} in {os.path.basename(motion.source)}", fontsize=9)
    left.legend(loc="upper right", fontsize=8)
    right.plot(t[valid], wrap_pi(run["theta"] - offline)[valid], lw=0.8)
    right.axhline(0.0, color="0.5", lw=0.6)
    right.set_xlabel("t [s]")
    right.set_ylabel("online − offline [rad]")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
