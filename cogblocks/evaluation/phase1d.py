"""Accuracy of the online 1D phase estimator on simulated sensors: any rate, unit, quantisation and noise.

Each cell of the grid is one sensor condition; its signals come from :func:`cogblocks.data.sensor.simulate_sensor`
(60 s by default, with drop-outs, spikes and timestamp jitter) and are run through :class:`PhaseEstimator` at
the sensor's rate, with its defaults. Errors are ``|wrap_π(θ − φ)|`` against the true phase ``φ`` on every tick
after the first two periods of the movement (drop-outs included: there θ is extrapolated); the held share is
the share of ticks, after the first two periods and outside the simulated bad samples (missing, frozen,
spikes), on which the estimator reports ``held``. The offline reference is :func:`hilbert_phase` of the
recording with its bad samples interpolated, centred by a 0.2 Hz high-pass, on the same ticks.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np

from cogblocks.blocks.angles import wrap_pi
from cogblocks.data.sensor import simulate_sensor
from cogblocks.phase.estimator import PhaseEstimator
from cogblocks.phase.offline import hilbert_phase
from cogblocks.sim import Simulator

__all__ = [
    "EVALUATION_SEEDS",
    "NOISE",
    "QUANTISATION",
    "RATES",
    "SCALES",
    "TUNING_SEEDS",
    "evaluate_grid",
    "evaluate_signal",
    "plot_grid",
]

RATES = (25.0, 40.0, 60.0, 100.0, 120.0, 240.0)
SCALES = (0.01, 1.0, 1000.0)
#: quantisation step and noise standard deviation, relative to the movement's base amplitude
QUANTISATION = {"none": 0.0, "coarse": 0.05}
NOISE = {"low": 0.005, "high": 0.03}
#: seeds of the signals the defaults were chosen on, and of the signals they are judged on (disjoint)
TUNING_SEEDS = tuple(range(0, 10))
EVALUATION_SEEDS = tuple(range(1000, 1010))


def evaluate_signal(
    rate_hz: float,
    scale: float,
    quantised: str,
    noise: str,
    seed: int,
    *,
    duration: float = 60.0,
    estimator: dict[str, Any] | None = None,
) -> dict[str, np.ndarray]:
    """Run the estimator on one simulated recording.

    Returns
    -------
    dict
        ``error`` and ``hilbert_error`` (rad, on the ticks after the first two periods) and ``held`` (bool,
        on those of them outside the simulated bad samples).
    """
    cell = (int(round(rate_hz)), int(round(np.log10(scale) * 10)) + 100, quantised == "coarse", noise == "high")
    rng = np.random.default_rng([seed, *cell])
    rec = simulate_sensor(
        duration, rate_hz=rate_hz, seed=rng, scale=scale, quantisation=QUANTISATION[quantised], noise=NOISE[noise]
    )
    sim = Simulator(PhaseEstimator(**(estimator or {})), rec.dt, probes={"theta": "theta", "held": "held"})
    trace = sim.run(n_steps=len(rec.value), inputs={"p": rec.value})
    unwrapped = np.unwrap(rec.phase)
    after = unwrapped - unwrapped[0] >= 4.0 * np.pi
    filled = rec.value.copy()
    good = ~rec.bad
    filled[~good] = np.interp(np.flatnonzero(~good), np.flatnonzero(good), rec.value[good])
    reference = hilbert_phase(filled, dt=rec.dt, highpass=0.2)
    return {
        "error": np.abs(wrap_pi(trace["theta"] - rec.phase))[after],
        "hilbert_error": np.abs(wrap_pi(reference - rec.phase))[after],
        "held": np.asarray(trace["held"], dtype=bool)[after & good],
    }


def _cell(args: tuple) -> dict[str, Any]:
    rate_hz, scale, quantised, noise, seeds, duration, estimator = args
    runs = [evaluate_signal(rate_hz, scale, quantised, noise, s, duration=duration, estimator=estimator) for s in seeds]
    error = np.concatenate([r["error"] for r in runs])
    hilbert = np.concatenate([r["hilbert_error"] for r in runs])
    held = np.concatenate([r["held"] for r in runs])
    return {
        "rate_hz": rate_hz,
        "scale": scale,
        "quantised": quantised,
        "noise": noise,
        "mean_error_rad": float(error.mean()),
        "p95_error_rad": float(np.percentile(error, 95)),
        "held_share": float(held.mean()),
        "hilbert_mean_error_rad": float(hilbert.mean()),
        "hilbert_p95_error_rad": float(np.percentile(hilbert, 95)),
    }


def evaluate_grid(
    *,
    rates: Iterable[float] = RATES,
    scales: Iterable[float] = SCALES,
    quantisations: Iterable[str] = tuple(QUANTISATION),
    noises: Iterable[str] = tuple(NOISE),
    seeds: Sequence[int] = EVALUATION_SEEDS,
    duration: float = 60.0,
    estimator: dict[str, Any] | None = None,
    workers: int = 1,
) -> dict[str, Any]:
    """Mean and 95th-percentile error and held share of :class:`PhaseEstimator` in every cell of a grid.

    Parameters
    ----------
    rates, scales, quantisations, noises
        The grid: sampling rates in Hz, unit scales, keys of :data:`QUANTISATION` and :data:`NOISE`.
    seeds : sequence of int
        Signals per cell (each cell draws its own signals from the seed and the cell).
    duration : float
        Length of each signal in seconds.
    estimator : dict, optional
        Keyword arguments of :class:`PhaseEstimator` (its defaults when omitted).
    workers : int
        Processes that share the cells (1 runs them here).

    Returns
    -------
    dict
        ``{"cells": [{"rate_hz", "scale", "quantised", "noise", "mean_error_rad", "p95_error_rad",
        "held_share", "hilbert_mean_error_rad", "hilbert_p95_error_rad"}], "worst_mean_error_rad",
        "worst_p95_error_rad", "worst_held_share", "seeds"}``.
    """
    for name, given, allowed in (("quantisations", quantisations, QUANTISATION), ("noises", noises, NOISE)):
        given = tuple(given)
        if not set(given) <= set(allowed):
            raise ValueError(f"evaluate_grid: {name} must be among {sorted(allowed)}, got {given!r}")
    jobs = [
        (float(r), float(s), q, n, tuple(seeds), duration, estimator)
        for r, s, q, n in itertools.product(rates, scales, quantisations, noises)
    ]
    if workers > 1:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            cells = list(pool.map(_cell, jobs))
    else:
        cells = [_cell(job) for job in jobs]
    return {
        "cells": cells,
        "worst_mean_error_rad": max(c["mean_error_rad"] for c in cells),
        "worst_p95_error_rad": max(c["p95_error_rad"] for c in cells),
        "worst_held_share": max(c["held_share"] for c in cells),
        "seeds": list(seeds),
    }


def plot_grid(result: dict[str, Any], path: str) -> None:
    """Save heat maps of a grid's mean error, 95th percentile and held share (rows: rates; columns: conditions)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cells = result["cells"]
    rates = sorted({c["rate_hz"] for c in cells})
    columns = sorted(
        {(c["scale"], c["quantised"], c["noise"]) for c in cells}, key=lambda x: (x[0], x[1] != "none", x[2])
    )
    metrics = (("mean_error_rad", "mean error (rad)", 0.15), ("p95_error_rad", "p95 error (rad)", 0.5))
    metrics += (("held_share", "held share", 0.01),)
    fig, axes = plt.subplots(len(metrics), 1, figsize=(1.0 + 0.75 * len(columns), 2.2 * len(metrics) + 1.0))
    for ax, (key, title, goal) in zip(np.atleast_1d(axes), metrics, strict=True):
        table = np.full((len(rates), len(columns)), np.nan)
        for c in cells:
            table[rates.index(c["rate_hz"]), columns.index((c["scale"], c["quantised"], c["noise"]))] = c[key]
        image = ax.imshow(table / goal, cmap="RdYlGn_r", vmin=0.0, vmax=2.0, aspect="auto")
        for (i, j), value in np.ndenumerate(table):
            ax.text(
                j,
                i,
                f"{100 * value:.1f}" if key == "held_share" else f"{value:.3f}",
                ha="center",
                va="center",
                fontsize=7,
            )
        ax.set_yticks(range(len(rates)), [f"{r:g} Hz" for r in rates])
        ax.set_xticks(range(len(columns)), [f"×{s:g}\n{q}\n{n}" for s, q, n in columns], fontsize=7)
        ax.set_title(f"{title}{' (%)' if key == 'held_share' else ''}; colour: value / goal ({goal:g})", fontsize=9)
        fig.colorbar(image, ax=ax, fraction=0.02)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
