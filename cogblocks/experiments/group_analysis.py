"""A recorded group session, analysed: each participant's phase, the order parameter r(t), and a surrogate test.

Each participant is one marker of a C3D or XDF file (:func:`~cogblocks.data.recordings.load_recording`).
Their phase is computed twice: offline, by the PCA-Hilbert reference
(:func:`~cogblocks.phase.offline_phase_pca_hilbert`, gaps bridged linearly first), and online, by
the :class:`~cogblocks.phase.PhaseEstimator3D` a live run would use (its reference the participant's
own mean cycle, :func:`~cogblocks.phase.mean_cycle`). Both count phase 0 at a landmark of the
movement (the maximum of the position's projection on its principal direction, ``anchor=False``),
not at each person's own start, so that the phases of people making the same movement in the same
frame compare (people facing each other mirror it, and come out half a cycle apart). The online
estimator counts from the start of motion (assumption 3 of section 6.1.1); the constant between the
two offline conventions moves it to the landmark. The group's order parameter is
``r(t) = |mean_i exp(i θ_i(t))|`` over the ticks every participant has a phase on (seen, and for
the Hilbert phase more than one mean period from either end of the recording and an eighth of one
from a gap, where it is unreliable).

*Is the synchronisation above chance?* A group of people moving at similar tempos has a sizeable
time-averaged r even when nobody pays attention to anyone. The test compares the observed time
average with the same statistic on surrogates that keep each participant's own movement and break
only their alignment in time: each participant but the first is shifted circularly in time by an
independent random lag of at least two mean periods (and at most the length minus that). Surrogates
that shuffle each participant's cycles are not offered: the phase after k shuffled cycles differs from
the original only by the spread of the cycle lengths, so for regular movers they stay aligned as the
recording was, and even independent oscillators can come out above such surrogates.

The p-value is ``(1 + #{surrogate ≥ observed}) / (1 + n_surrogates)``, the Monte Carlo p-value of a
one-sided test (the convention of ``scipy.stats.monte_carlo_test``). When the file marks conditions
(C3D events, XDF marker streams: an event's label holds from its time to the next event), every
condition gets its own r and test.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

import numpy as np
import scipy.ndimage
import scipy.stats

from cogblocks.blocks.angles import TWO_PI, wrap_2pi, wrap_pi
from cogblocks.data.markers import MarkerRecording
from cogblocks.data.recordings import load_recording
from cogblocks.diagrams.phase3d import run_phase_estimator
from cogblocks.diagrams.recording import RecordedMotion, filled
from cogblocks.phase import mean_cycle, offline_phase_pca_hilbert
from cogblocks.sim.timing import BASE_STEP

__all__ = ["SURROGATES", "analyse_group", "order_parameter", "surrogate_test"]

SURROGATES = ("shift",)
_MIN_SHIFT_PERIODS = 2.0


def order_parameter(theta: np.ndarray) -> np.ndarray:
    """``r(t) = |mean_i exp(i θ_i(t))|`` of phases of shape (N, n): shape (n,)."""
    return 1.0 - scipy.stats.circvar(np.asarray(theta), axis=0)  # scipy's circular variance is 1 − r


def surrogate_test(
    theta: np.ndarray,
    usable: np.ndarray,
    *,
    n_surrogates: int = 199,
    kind: str = "shift",
    seed: int | np.random.Generator = 0,
) -> dict[str, Any]:
    """Time-averaged r of phases against surrogates that break the participants' alignment.

    Parameters
    ----------
    theta : numpy.ndarray, shape (N, n)
        Phases in rad on a common grid.
    usable : numpy.ndarray of bool, shape (N, n)
        Where each phase counts; r(t) is averaged over the ticks where all count.
    n_surrogates : int
        Number of surrogates (>= 19 for a p-value that can reach 0.05).
    kind : {"shift"}
        Surrogate family: circular time shifts (see the module's description).
    seed : int or numpy.random.Generator
        Seed of the surrogates.

    Returns
    -------
    dict
        ``r_mean`` (observed), ``null_mean`` and ``null_p95`` (of the surrogates), ``p_value``,
        ``n_surrogates``, ``surrogate`` and ``null`` (the surrogates' time-averaged r, an array).
    """
    theta = np.asarray(theta, dtype=np.float64)
    usable = np.asarray(usable, dtype=bool)
    if theta.ndim != 2 or theta.shape[0] < 2 or usable.shape != theta.shape:
        raise ValueError(f"surrogate_test: theta and usable must be (N >= 2, n) arrays, got {theta.shape}")
    if kind not in SURROGATES:
        raise ValueError(f"surrogate_test: kind must be one of {', '.join(SURROGATES)}, got {kind!r}")
    if not (isinstance(n_surrogates, int) and n_surrogates >= 19):
        raise ValueError(f"surrogate_test: n_surrogates must be an integer >= 19, got {n_surrogates!r}")
    both = usable.all(axis=0)
    if both.sum() < 2:
        raise ValueError("surrogate_test: fewer than 2 ticks on which every participant has a phase")
    observed = float(order_parameter(theta[:, both]).mean())
    rng = np.random.default_rng(seed)
    period = _mean_period(theta, usable)
    null = np.empty(n_surrogates)
    for s in range(n_surrogates):
        surrogate, mask = _shifted(theta, usable, period, rng)
        common = mask.all(axis=0)
        null[s] = order_parameter(surrogate[:, common]).mean() if common.sum() >= 2 else 0.0
    return {
        "r_mean": observed,
        "null_mean": float(null.mean()),
        "null_p95": float(np.percentile(null, 95)),
        "p_value": float((1 + np.count_nonzero(null >= observed)) / (1 + n_surrogates)),
        "n_surrogates": n_surrogates,
        "surrogate": kind,
        "null": null,
    }


def analyse_group(
    recording: str | os.PathLike | MarkerRecording,
    markers: Sequence[str],
    *,
    dt: float = BASE_STEP,
    online: bool = True,
    n_surrogates: int = 199,
    surrogate: str = "shift",
    seed: int = 0,
    alpha: float = 0.05,
) -> dict[str, Any]:
    """Phases, r(t) and the surrogate test of a recorded group (one marker per participant).

    Parameters
    ----------
    recording : path or MarkerRecording
        A C3D or XDF file, or a loaded recording.
    markers : sequence of str
        One marker per participant (at least 2).
    dt : float
        Tick of the grid the recording is resampled onto, in s.
    online : bool
        Also run the online estimator (a few seconds per participant-minute).
    n_surrogates, surrogate, seed
        See :func:`surrogate_test`.
    alpha : float
        Level at which ``above_chance`` is decided.

    Returns
    -------
    dict
        ``file``, ``markers``, ``duration_s``, ``dt``, ``offline`` (the test on the Hilbert phases:
        see :func:`surrogate_test`, plus ``above_chance``), ``online`` (the same on the online phases,
        plus ``mean_error_vs_offline_rad``; None with ``online=False``), ``conditions`` (label →
        ``{"duration_s", "offline": test}``, empty when the file marks none), and the arrays ``t``,
        ``r_offline`` and ``r_online`` (r(t), NaN where not every participant has a phase) under
        ``series``.
    """
    if len(markers) < 2:
        raise ValueError(f"analyse_group: a group needs at least 2 markers, got {list(markers)}")
    rec = recording.select(list(markers)).resampled(dt) if isinstance(recording, MarkerRecording) else None
    rec = rec if rec is not None else load_recording(recording, list(markers), dt=dt)
    t = rec.t - rec.t[0]
    seen = np.isfinite(rec.points).all(axis=2).T  # (N, n)
    offline = np.empty(seen.shape)
    for i, name in enumerate(rec.markers):
        try:
            offline[i] = offline_phase_pca_hilbert(filled(rec.points[:, i]), anchor=False)
        except ValueError as error:
            raise ValueError(f"{rec.source}: marker {name!r}: {error}") from None
    edge = int(np.ceil(_mean_period(offline, seen)))
    inner = np.zeros(len(t), dtype=bool)
    inner[edge : len(t) - edge] = True
    # the Hilbert phase of a bridged gap is off for a few ticks past its edges: leave an eighth of a period
    margin = max(1, edge // 8)
    near_gap = scipy.ndimage.binary_dilation(~seen, structure=np.ones((1, 2 * margin + 1), dtype=bool))
    usable_offline = ~near_gap & inner
    options = {"n_surrogates": n_surrogates, "kind": surrogate, "seed": seed}
    result: dict[str, Any] = {
        "file": rec.source,
        "markers": list(rec.markers),
        "duration_s": float(len(t) * dt),
        "dt": dt,
        "offline": _decided(surrogate_test(offline, usable_offline, **options), alpha),
        "online": None,
        "conditions": {},
    }
    r_offline = np.where(usable_offline.all(axis=0), order_parameter(offline), np.nan)
    r_online = np.full(len(t), np.nan)
    if online:
        theta = np.empty(seen.shape)
        valid = np.empty(seen.shape, dtype=bool)
        for i, name in enumerate(rec.markers):
            position = rec.points[:, i]
            motion = RecordedMotion(t, position, mean_cycle(filled(position)), dt, name, rec.source)
            run = run_phase_estimator(motion)
            valid[i] = run["valid"] & seen[i]
            # from the start-of-motion origin to the landmark: the constant between the two offline conventions
            shift = scipy.stats.circmean(offline[i] - offline_phase_pca_hilbert(filled(position)))
            theta[i] = wrap_2pi(run["theta"] + shift)
        test = _decided(surrogate_test(theta, valid, **options), alpha)
        both = valid & usable_offline
        diff = np.abs(wrap_pi(theta[both] - offline[both]))
        test["mean_error_vs_offline_rad"] = float(diff.mean()) if diff.size else None
        result["online"] = test
        r_online = np.where(valid.all(axis=0), order_parameter(theta), np.nan)
    events = tuple((label, time - rec.t[0]) for label, time in rec.events)  # on the same clock as t
    for label, mask in _conditions(events, t, dt).items():
        # the condition's ticks alone: surrogates shift within them, never into another condition
        entry: dict[str, Any] = {"duration_s": float(mask.sum() * dt)}
        try:
            entry["offline"] = _decided(surrogate_test(offline[:, mask], usable_offline[:, mask], **options), alpha)
        except ValueError as error:  # a condition too short to test
            entry["offline"] = None
            entry["note"] = str(error)
        result["conditions"][label] = entry
    result["series"] = {"t": t, "r_offline": r_offline, "r_online": r_online}
    return result


def _decided(test: dict[str, Any], alpha: float) -> dict[str, Any]:
    return {**test, "above_chance": bool(test["p_value"] <= alpha)}


def _conditions(events: tuple[tuple[str, float], ...], t: np.ndarray, dt: float) -> dict[str, np.ndarray]:
    """Each event's label holds from its time to the next event's; labels that repeat are merged."""
    out: dict[str, np.ndarray] = {}
    for k, (label, start) in enumerate(events):
        stop = events[k + 1][1] if k + 1 < len(events) else np.inf
        mask = (t >= start - 0.5 * dt) & (t < stop - 0.5 * dt)
        out[label] = out.get(label, np.zeros(len(t), dtype=bool)) | mask
    return out


def _mean_period(theta: np.ndarray, usable: np.ndarray) -> float:
    """Mean period in samples over the participants, from the median phase increment."""
    steps = wrap_pi(np.diff(theta, axis=1))
    ok = usable[:, 1:] & usable[:, :-1]
    step = float(np.median(np.abs(steps[ok]))) if ok.any() else 0.0
    return TWO_PI / step if step > 0 else float(theta.shape[1])


def _shifted(
    theta: np.ndarray, usable: np.ndarray, period: float, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    n = theta.shape[1]
    low = min(int(np.ceil(_MIN_SHIFT_PERIODS * period)), n // 2)
    shifts = np.r_[0, rng.integers(low, n - low + 1, size=theta.shape[0] - 1)]
    rows = np.arange(n)
    index = (rows[None, :] - shifts[:, None]) % n
    return np.take_along_axis(theta, index, axis=1), np.take_along_axis(usable, index, axis=1)
