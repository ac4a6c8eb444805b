"""L1 delay compensation on synthetic motion-capture streams: RMS error to the true current position.

For 1-D and 3-D oscillations (0.5-1 Hz, 100-300 mm) received late by 50, 100 or
200 ms with 2 mm noise, missing frames, frozen stretches and spikes, compare the
error to the TRUE CURRENT position of

* ``raw``: the delayed stream as a naive avatar would show it (missing frames
  hold the last finite sample);
* ``smoothed``: the Kalman estimate of the delayed stream (``L1(delay=0)``);
* ``compensated``: the L1 output, predicted ahead by the delay (ca model);
* ``compensated_cv``: the same with the constant-velocity model;
* ``compensated_noise_only``: ``compensated`` on the same stream with noise
  but no bad data (its ``reference`` stays the raw RMS of the bad stream), to
  separate the cost of bad data from that of extrapolation.

Prints one JSON object per line; ``reference`` is the raw delayed RMS and
``ratio = value / reference``. Run: ``python benchmarks/l1_delay.py``.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Iterator

import numpy as np

from cogblocks.blocks import Playback
from cogblocks.sensing import L1, KalmanEstimator
from cogblocks.sim import Diagram, Simulator

DT = 0.01
DELAYS_MS = (50, 100, 200)
WARM_UP = 100  # frames left out of the RMS: the filter's start-up


def true_motion(t: np.ndarray, dims: int) -> np.ndarray:
    """Oscillations whose frequency drifts over 0.5-1 Hz and amplitude over 100-300 mm; shape (T, dims)."""
    # frequency f(t) = 0.75 + 0.25 sin(2π t / 17) Hz; phase = ∫ 2π f dt in closed form
    phase = 2 * np.pi * (0.75 * t - 0.25 * 17.0 / (2 * np.pi) * np.cos(2 * np.pi * t / 17.0))
    amp = 200.0 + 100.0 * np.sin(2 * np.pi * t / 23.0 + 1.0)
    axes = [amp * np.sin(phase), 0.6 * amp * np.sin(phase + 1.2), 0.4 * amp * np.sin(0.5 * phase + 0.3) + 50.0]
    return np.stack(axes[:dims], axis=1)


def corrupt(noisy: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Add 2 % missing frames, three 15-frame gaps, three 20-frame freezes and ten spikes to a noisy stream."""
    n = len(noisy)
    z = noisy.copy()
    for start in rng.choice(np.arange(200, n - 50), size=3, replace=False):
        z[start : start + 20] = z[start - 1]
    for i in rng.choice(np.arange(200, n), size=10, replace=False):
        axis = rng.integers(noisy.shape[1])
        z[i, axis] += rng.choice([-1.0, 1.0]) * rng.uniform(40.0, 100.0)
    z[rng.random(n) < 0.02] = np.nan
    for start in rng.choice(np.arange(200, n - 50), size=3, replace=False):
        z[start : start + 15] = np.nan
    return z


def hold_last(z: np.ndarray) -> np.ndarray:
    """What a naive avatar shows: the last finite sample (the first one before any)."""
    held = z.copy()
    first = np.flatnonzero(np.isfinite(z).all(axis=1))[0]
    held[:first] = z[first]
    for i in range(first + 1, len(z)):
        if not np.isfinite(held[i]).all():
            held[i] = held[i - 1]
    return held


def run_l1(z: np.ndarray, delay: float, model: str) -> tuple[np.ndarray, np.ndarray]:
    """The L1 output and its estimator's smoothed position for the stream ``z``."""
    dims = z.shape[1]
    d = Diagram()
    d.add("src", Playback(z if dims > 1 else z[:, 0], unit="mm"))
    d.add("l1", L1(delay, estimator=KalmanEstimator(model, dims=dims)))
    d.connect("src.y", "l1.p")
    trace = Simulator(d, DT, probes={"avatar": "l1.p_avatar", "smoothed": "l1.kalman.p_hat"}).run(n_steps=len(z))
    return trace["avatar"].reshape(len(z), dims), trace["smoothed"].reshape(len(z), dims)


def rms(estimate: np.ndarray, truth: np.ndarray) -> float:
    """RMS over frames of the Euclidean error, after the warm-up."""
    err = estimate[WARM_UP:] - truth[WARM_UP:]
    return float(np.sqrt(np.mean(np.sum(err**2, axis=1))))


def run(quick: bool = False, duration: float | None = None, seed: int = 0) -> Iterator[dict]:
    """Yield the RMS errors for every dimension, delay and variant (``quick``: 15 s of motion)."""
    n = round((duration or (15.0 if quick else 60.0)) / DT)
    for dims in (1, 3):
        for delay_ms in DELAYS_MS:
            rng = np.random.default_rng([seed, dims, delay_ms])
            t = np.arange(n) * DT
            truth = true_motion(t, dims)
            noisy = true_motion(t - delay_ms / 1000.0, dims) + 2.0 * rng.standard_normal((n, dims))
            z = corrupt(noisy, rng)
            reference = rms(hold_last(z), truth)
            compensated, smoothed = run_l1(z, delay_ms / 1000.0, "ca")
            compensated_cv, _ = run_l1(z, delay_ms / 1000.0, "cv")
            noise_only, _ = run_l1(noisy, delay_ms / 1000.0, "ca")
            results = {
                "raw": reference,
                "smoothed": rms(smoothed, truth),
                "compensated": rms(compensated, truth),
                "compensated_cv": rms(compensated_cv, truth),
                "compensated_noise_only": rms(noise_only, truth),
            }
            for kind, value in results.items():
                yield {
                    "name": f"l1.rms.{dims}d.delay{delay_ms}ms.{kind}",
                    "value": round(value, 3),
                    "unit": "mm",
                    "reference": round(reference, 3),
                    "ratio": round(value / reference, 4),
                }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=60.0, help="seconds of motion (default 60)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    for result in run(duration=args.duration, seed=args.seed):
        print(json.dumps(result))


if __name__ == "__main__":
    main()
