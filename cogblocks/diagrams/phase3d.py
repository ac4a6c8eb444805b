"""3D phase estimation (section 6): the phase chain, the estimator's accuracy, the Figure 14 analogue.

:func:`phase_chain` runs the synchronisation architecture on 3D hand motion: the assisted
person's positions → :class:`~cogblocks.phase.PhaseEstimator3D` → the L2 block of the
Social Connectedness PoP → :class:`~cogblocks.phase.PhasePositionComputer` → the avatar's 3D
positions, with the other participants' phases from a Kuramoto group that sees the avatar.

The online estimator (:class:`~cogblocks.phase.PhaseEstimator3D`) runs on synthetic hand
trajectories (:func:`~cogblocks.data.motion3d.generate_motion3d`) whose phase is known, and is
compared with the ground truth and with the offline PCA-Hilbert estimate
(:func:`~cogblocks.phase.offline_phase_pca_hilbert`). Errors are circular,
``|wrap_π(θ_a − θ_b)|``, and counted only once the online estimate is valid (after the first
period, the calibration period of Figure 14).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from cogblocks.blocks import Playback, Probe, Substitute
from cogblocks.blocks.angles import wrap_pi
from cogblocks.data.groups import TABLE2, SyncGroup
from cogblocks.data.motion3d import Motion3D, generate_motion3d
from cogblocks.diagrams.sync import MOTIONS
from cogblocks.phase import PhaseEstimator3D, PhasePositionComputer, offline_phase_pca_hilbert
from cogblocks.sim import Block, Diagram, Simulator
from cogblocks.sim.params import finite_number, one_of, positive_int
from cogblocks.sync import Blender, KuramotoGroup, L2Sync, OrderParameter

__all__ = [
    "MOTION3D_SETS",
    "chain_summary",
    "phase3d_accuracy",
    "phase_chain",
    "plot_phase3d",
    "run_phase_chain",
    "run_phase_estimator",
]

#: Named sets of synthetic trajectories (changes to :func:`generate_motion3d`'s defaults). ``"today"``:
#: the defaults (up to 20° of rotation, 5 % drifts, drop-outs of 2-8 samples). ``"harder"``: rotations
#: up to 180°, the phase speed ±20 % within each cycle, drop-outs of 100-300 ms, 10 % drifts.
MOTION3D_SETS: dict[str, dict[str, Any]] = {
    "today": {},
    "harder": {
        "rotation_deg": 180.0,
        "speed_wobble": 0.2,
        "dropout_duration": (0.1, 0.3),
        "period_drift": 0.1,
        "amplitude_drift": 0.1,
    },
}


def phase_chain(
    motion: Motion3D,
    group: SyncGroup | int = 3,
    motion_computer: str | Block = "mean",
    blender: Blender | None = None,
    avatar_noise_mm: float = 0.0,
    seed: int = 0,
) -> Diagram:
    """The synchronisation architecture on 3D motion, as one diagram.

    Blocks: ``human`` plays the assisted person's tracked positions; ``estimator``
    (:class:`PhaseEstimator3D` on the motion's reference) gives θ_L0; ``group`` is a Kuramoto
    group for everyone (its assisted participant's own phase is replaced by the estimate in
    ``theta``); ``l2`` (:class:`L2Sync`) blends θ_L0 with the motion computer's reference;
    ``avatar`` (:class:`PhasePositionComputer`) turns θ_L2 back into 3D positions on the reference
    (the avatar moves in the reference's frame); ``order`` measures the group as it sees the
    avatar. Probes: ``r``, ``avatar_p``.

    Parameters
    ----------
    motion : Motion3D
        The assisted person's trajectory and the reference primitive (or a recording's
        :class:`~cogblocks.diagrams.recording.RecordedMotion`: ``position`` and ``reference``).
    group : SyncGroup or int
        The other participants (Table 2's group number by default 3, whose frequencies are those
        of arm motion at ~0.5 Hz).
    motion_computer : str or Block
        A name from :data:`cogblocks.diagrams.sync.MOTIONS` or a motion computer block.
    blender : Blender, optional
        The deliverable's blender by default.
    avatar_noise_mm : float
        White noise added to the avatar's positions (section 6.2.2), in mm.
    seed : int
        Seed of that noise.

    Notes
    -----
    Until the estimator has seen its first period (``estimator.valid`` is False) θ_L0 is held at
    0, so the L2 output is meaningful only after it.
    """
    params = TABLE2[group] if isinstance(group, int) else group
    a = params.assisted
    d = Diagram()
    human = d.add("human", Playback(motion.position, unit="mm"))
    estimator = d.add("estimator", PhaseEstimator3D(motion.reference))
    d.connect(human.y, estimator.p)
    kuramoto = d.add("group", KuramotoGroup(params.omega, params.gain, assisted=a))
    theta = d.add("theta", Substitute(a))
    d.connect(kuramoto.theta, theta.u)
    d.connect(estimator.theta, theta.v)
    mc = MOTIONS[motion_computer](params) if isinstance(motion_computer, str) else motion_computer
    l2 = d.add("l2", L2Sync(mc, a, blender))
    d.connect(theta.y, l2.theta)
    seen = d.add("seen", Substitute(a))
    d.connect(theta.y, seen.u)
    d.connect(l2.theta_l2, kuramoto.theta_l2, seen.v)
    order = d.add("order", OrderParameter())
    d.connect(seen.y, order.theta)
    avatar = d.add("avatar", PhasePositionComputer(motion.reference, noise_std=avatar_noise_mm, seed=seed))
    d.connect(l2.theta_l2, avatar.theta)
    d.add("r", Probe())
    d.connect(order.r, "r.u")
    d.add("avatar_p", Probe())
    d.connect(avatar.p, "avatar_p.u")
    return d


def run_phase_chain(seed: int = 0, duration: float = 30.0, motion_computer: str = "mean") -> dict[str, Any]:
    """Run :func:`phase_chain` on one synthetic trajectory; report the group's synchrony and the avatar.

    Returns
    -------
    dict
        ``r_mean`` (order parameter with the avatar, once the estimate is valid), ``valid_from_s``,
        ``mean_dev_rad`` / ``max_dev_rad`` (``|θ_L2 − θ_L0|`` once valid) and
        ``avatar_path_mm`` (length of the avatar's path).
    """
    return chain_summary(generate_motion3d(seed, duration=duration), motion_computer)


def chain_summary(motion: Any, motion_computer: str = "mean") -> dict[str, Any]:
    """Run :func:`phase_chain` on ``motion`` (a :class:`Motion3D` or any object with ``position``,
    ``reference``, ``t`` and ``dt``, such as a recording's :class:`~cogblocks.diagrams.recording.RecordedMotion`)
    and report what :func:`run_phase_chain` reports."""
    sim = Simulator(
        phase_chain(motion, motion_computer=motion_computer),
        dt=motion.dt,
        probes={"valid": "estimator.valid", "theta_l2": "l2.theta_l2", "theta_l0": "l2.theta_l0"},
    )
    trace = sim.run(n_steps=len(motion.t))
    valid = trace["valid"]
    if not valid.any():
        raise ValueError(f"the estimator found no complete period in {motion.t[-1] - motion.t[0]:.2f} s of motion")
    dev = np.abs(wrap_pi(trace["theta_l2"][valid] - trace["theta_l0"][valid]))
    path = np.linalg.norm(np.diff(trace["avatar_p"], axis=0), axis=1).sum()
    return {
        "r_mean": float(trace["r"][valid].mean()),
        "valid_from_s": float(trace.t[np.argmax(valid)]),
        "mean_dev_rad": float(dev.mean()),
        "max_dev_rad": float(dev.max()),
        "avatar_path_mm": float(path),
    }


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
    rate_hz: float = 100.0,
    motion_set: str = "today",
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
    rate_hz : float
        Sampling rate of the trajectories in Hz (5-1000; 100 by default).
    motion_set : str
        A key of :data:`MOTION3D_SETS` (``"today"`` by default).
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
        statistics), ``duration``, ``rate_hz``, ``seed`` and ``set``.
    """
    n_trajectories = positive_int("phase3d_accuracy", "n_trajectories", n_trajectories)
    duration = finite_number("phase3d_accuracy", "duration", duration, low=6.0)
    rate_hz = finite_number("phase3d_accuracy", "rate_hz", rate_hz, low=5.0, high=1000.0)
    changes = MOTION3D_SETS[one_of("phase3d_accuracy", "motion_set", motion_set, MOTION3D_SETS)]
    online, versus_offline, offline = [], [], []
    first_errors, valid_counts, n_total = [], [], 0
    for child in np.random.SeedSequence(seed).spawn(n_trajectories):
        motion = generate_motion3d(np.random.default_rng(child), duration=duration, dt=1.0 / rate_hz, **changes)
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
        "rate_hz": rate_hz,
        "seed": seed,
        "set": motion_set,
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
