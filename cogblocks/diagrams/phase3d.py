"""3D phase estimation (section 6): accuracy of the online estimator and the Figure 14 analogue.

The online estimator (:class:`~cogblocks.blocks.phase3d.PhaseEstimator3D`) runs on synthetic hand
trajectories (:func:`~cogblocks.data.motion3d.generate_motion3d`) whose phase is known, and is
compared with the ground truth and with the offline PCA-Hilbert estimate
(:func:`~cogblocks.blocks.phase3d.offline_phase_pca_hilbert`). Errors are circular,
``|wrap_π(θ_a − θ_b)|``, and counted only once the online estimate is valid (after the first
period, the calibration period of Figure 14).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from cogblocks.blocks.angles import wrap_pi
from cogblocks.blocks.phase3d import PhaseEstimator3D, offline_phase_pca_hilbert
from cogblocks.data.motion3d import Motion3D, generate_motion3d
from cogblocks.sim import Simulator
from cogblocks.sim.params import finite_number, positive_int

__all__ = ["phase3d_accuracy", "plot_phase3d", "run_phase_estimator"]


def run_phase_estimator(motion: Motion3D, **estimator_kwargs: Any) -> dict[str, np.ndarray]:
    """Run a :class:`PhaseEstimator3D` on a recorded trajectory.

    Parameters
    ----------
    motion : Motion3D
        The trajectory; its ``reference`` is the estimator's reference and its ``dt`` the step.
    **estimator_kwargs
        Passed to :class:`PhaseEstimator3D` (``h``, ``search``, ``window``, ...).

    Returns
    -------
    dict
        ``theta`` (rad), ``valid`` (bool) and ``first_period`` (the length in samples of the
        first period the estimator detected, 0 if it found none), one entry per sample.
    """
    estimator = PhaseEstimator3D(motion.reference, **estimator_kwargs)
    sim = Simulator(
        estimator,
        dt=motion.dt,
        probes={"theta": "phase.theta", "valid": "phase.valid", "length": "period.last_length"},
    )
    trace = sim.run(n_steps=len(motion.t), inputs={"p": motion.position})
    valid = trace["valid"]
    first = int(trace["length"][np.argmax(valid)]) if valid.any() else 0
    return {"theta": trace["theta"], "valid": valid, "first_period": first}


def phase3d_accuracy(
    n_trajectories: int = 30,
    seed: int = 0,
    duration: float = 30.0,
    **estimator_kwargs: Any,
) -> dict[str, Any]:
    """Accuracy of the online 3D phase estimator over seeded synthetic trajectories.

    Each trajectory (default parameters of :func:`generate_motion3d`: 1 mm noise, drop-outs,
    period and amplitude drift, up to 20° of rotation) is estimated online with the default
    :class:`PhaseEstimator3D` and offline with :func:`offline_phase_pca_hilbert`. Errors are
    pooled over every sample of every trajectory at which the online estimate is valid.

    Parameters
    ----------
    n_trajectories : int
        Number of trajectories (>= 1).
    seed : int
        Seed of the whole set; trajectory ``i`` uses the ``i``-th child of
        ``numpy.random.SeedSequence(seed)``.
    duration : float
        Length of each trajectory in s (long enough for two cycles: >= 6 s).
    **estimator_kwargs
        Passed to :class:`PhaseEstimator3D`.

    Returns
    -------
    dict
        ``mean_error_rad`` and ``p95_error_rad`` (online vs ground truth),
        ``mean_error_vs_offline_rad`` and ``p95_error_vs_offline_rad`` (online vs offline),
        ``offline_mean_error_rad`` and ``offline_p95_error_rad`` (offline vs ground truth, over the
        same samples), ``worst_trajectory_mean_error_rad``, ``first_period_error_samples_max``
        (largest ``|detected − true|`` length of the first period), ``valid_share`` (share of the
        samples with a valid estimate), ``n_trajectories``, ``n_samples`` (samples in the
        statistics), ``duration`` and ``seed``.
    """
    n_trajectories = positive_int("phase3d_accuracy", "n_trajectories", n_trajectories)
    duration = finite_number("phase3d_accuracy", "duration", duration, low=6.0)
    online, versus_offline, offline = [], [], []
    first_errors, valid_counts, n_total = [], [], 0
    for child in np.random.SeedSequence(seed).spawn(n_trajectories):
        motion = generate_motion3d(np.random.default_rng(child), duration=duration)
        run = run_phase_estimator(motion, **estimator_kwargs)
        valid = run["valid"]
        offline_phase = offline_phase_pca_hilbert(motion.position)
        online.append(np.abs(wrap_pi(run["theta"][valid] - motion.phase[valid])))
        versus_offline.append(np.abs(wrap_pi(run["theta"][valid] - offline_phase[valid])))
        offline.append(np.abs(wrap_pi(offline_phase[valid] - motion.phase[valid])))
        first_errors.append(abs(run["first_period"] - motion.first_period))
        valid_counts.append(int(valid.sum()))
        n_total += len(valid)
    e_online, e_versus, e_offline = (np.concatenate(parts) for parts in (online, versus_offline, offline))
    return {
        "mean_error_rad": float(e_online.mean()),
        "p95_error_rad": float(np.percentile(e_online, 95)),
        "mean_error_vs_offline_rad": float(e_versus.mean()),
        "p95_error_vs_offline_rad": float(np.percentile(e_versus, 95)),
        "offline_mean_error_rad": float(e_offline.mean()),
        "offline_p95_error_rad": float(np.percentile(e_offline, 95)),
        "worst_trajectory_mean_error_rad": float(max(part.mean() for part in online)),
        "first_period_error_samples_max": int(max(first_errors)),
        "valid_share": float(sum(valid_counts) / n_total),
        "n_trajectories": n_trajectories,
        "n_samples": int(e_online.size),
        "duration": duration,
        "seed": seed,
    }


def plot_phase3d(path: str, seed: int = 0, duration: float = 30.0, shown: float = 12.0) -> dict[str, float]:
    """Draw the analogue of Figure 14 for one synthetic trajectory and save it to ``path``.

    Left: the online and offline phases (and the ground truth, thin) over the first ``shown``
    seconds, the calibration period shaded. Right: the circular error of the online estimate
    with respect to the offline one over the whole trajectory, the calibration period left out.

    Parameters
    ----------
    path : str
        Output file (png, pdf, svg).
    seed : int
        Seed of :func:`generate_motion3d`.
    duration : float
        Length of the trajectory in s (>= 6).
    shown : float
        Seconds shown in the left panel (> 0).

    Returns
    -------
    dict
        The mean circular errors of that trajectory once valid: ``mean_error_rad`` (online vs
        truth) and ``mean_error_vs_offline_rad``.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    duration = finite_number("plot_phase3d", "duration", duration, low=6.0)
    shown = finite_number("plot_phase3d", "shown", shown, low=0.0, low_open=True)
    motion = generate_motion3d(seed, duration=duration)
    run = run_phase_estimator(motion)
    theta, valid = run["theta"], run["valid"]
    offline_phase = offline_phase_pca_hilbert(motion.position)
    t = motion.t
    calibration_end = t[np.argmax(valid)] if valid.any() else t[-1]
    error = wrap_pi(theta - offline_phase)

    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 3.8))
    window = t < shown
    left.axvspan(0.0, calibration_end, color="0.9", label="calibration (first period)")
    left.plot(t[window], _break_wraps(motion.phase[window]), color="0.6", lw=0.8, label="ground truth")
    left.plot(t[window], _break_wraps(offline_phase[window]), lw=1.2, label="offline (PCA + Hilbert)")
    online_shown = np.where(valid, theta, np.nan)[window]  # no line where there is no estimate
    left.plot(t[window], _break_wraps(online_shown), lw=1.2, ls="--", label="online")
    left.set_xlabel("t [s]")
    left.set_ylabel("phase [rad]")
    left.set_ylim(0.0, 2.0 * np.pi)
    left.legend(loc="upper right", fontsize=8, framealpha=0.9)
    right.plot(t[valid], error[valid], lw=0.8)
    right.axhline(0.0, color="0.5", lw=0.6)
    right.set_xlim(0.0, t[-1])
    right.set_xlabel("t [s]")
    right.set_ylabel("online − offline [rad]")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return {
        "mean_error_rad": float(np.abs(wrap_pi(theta[valid] - motion.phase[valid])).mean()),
        "mean_error_vs_offline_rad": float(np.abs(error[valid]).mean()),
    }


def _break_wraps(phase: np.ndarray) -> np.ndarray:
    """A copy with NaN at each wrap, so that a plotted phase has no vertical line there."""
    out = phase.astype(float)
    out[1:][np.abs(np.diff(phase)) > np.pi] = np.nan
    return out
