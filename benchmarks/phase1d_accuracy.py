"""Accuracy of the online 1D phase estimator (Algorithm 1) on synthetic human oscillations.

For ``n`` seeded 60 s signals from :func:`cogblocks.data.oscillation.generate_oscillation`
(0.4-1.2 Hz, 100-300 mm, drifting; 1 mm noise; mild harmonics), in three data sets (``clean``:
no bad data; ``dropouts``: 4 frozen stretches of 0.1-0.5 s a minute on average;
``dropouts_nan``: the same and 1 % missing samples), run the module
:class:`cogblocks.phase.PhaseEstimator` and measure the circular error
``|wrap_pi(θ_online − θ_ref)|`` against

* ``hilbert``: the offline Hilbert phase of the drop-out-free signal
  (:func:`cogblocks.phase.hilbert_phase`, centred by a zero-phase 0.2 Hz high-pass);
* ``true``: the phase of the underlying oscillator.

The first and the last 5 s of every signal are left out: the start-up (the first period, at
most 2.5 s, and the first amplitude updates) and the Hilbert transform's end effects, which
reach a few seconds into a signal that is not a whole number of periods. Errors are pooled
over every remaining sample of every signal; ``mean`` and ``p95`` (95th percentile) are in
rad. ``reference`` and ``ratio`` are null.

Front ends: on the data sets with drop-outs (``dropouts``, ``dropouts_nan``) the same seeded
signals also go through ``PhaseEstimator(front_end="kalman")`` (a constant-acceleration Kalman
filter with its default noise in place of the low-pass filter and the backward differences).
Records ``phase1d.front_end.{lowpass,kalman}.<data set>.vs_{hilbert,true}.{mean,p95}``; for the
Kalman ones ``reference`` is the low-pass figure and ``ratio`` = Kalman / low-pass.

Run: ``python benchmarks/phase1d_accuracy.py [--quick] [--sweep] [--plot PNG]``
(``--sweep`` adds the low-pass cut-off, lag-compensation, centring and hold-off variants,
three stress data sets for the cut-off and an error budget; about 5 minutes on one core,
25 s without it).
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Iterator
from typing import Any

import numpy as np

from cogblocks.blocks.angles import wrap_pi
from cogblocks.data.oscillation import Oscillation, generate_oscillation
from cogblocks.phase import Algorithm1Phase, PhaseEstimator, hilbert_phase
from cogblocks.sim import Simulator

DT = 0.01
DURATION = 60.0
HILBERT_HIGHPASS = 0.2  # Hz: removes the offset drift, keeps 0.4-1.2 Hz
EDGE = 5.0  # s left out at both ends: the start-up (at most two periods) and the Hilbert end effects
CUTOFFS: list[tuple[str, dict[str, Any]]] = [(f"cutoff{fc:g}", {"cutoff": fc}) for fc in (2.0, 4.0, 6.0, 8.0)]
SWEEP: list[tuple[str, dict[str, Any]]] = [
    *CUTOFFS,
    *((f"cutoff{fc:g}", {"cutoff": fc}) for fc in (12.0, 20.0, 40.0)),
    *((f"cutoff{fc:g}.uncompensated", {"cutoff": fc, "compensate": False}) for fc in (4.0, 8.0, 20.0, 40.0)),
    ("centre1period", {"centre_periods": 1}),
    *((f"centre{w:g}s", {"fixed_window": w}) for w in (1.0, 2.0, 4.0)),
    *((f"holdoff{h:g}", {"holdoff": h}) for h in (0.0, 0.1, 0.3)),
    ("accel1step", {"accel_window": 0.0}),
]


DATASETS = {
    "clean": {"dropout_rate": 0.0},  # noise, drift and harmonics, but no bad data
    "dropouts": {"dropout_rate": 4.0},  # 4 frozen stretches of 0.1-0.5 s a minute on average
    "dropouts_nan": {"dropout_rate": 4.0, "nan_rate": 0.01},  # and 1 % missing samples
    # stress tests of the cut-off choice (with drop-outs; --sweep only)
    "fastdrift": {"dropout_rate": 4.0, "freq_drift": 0.4},  # frequency wandering ±40 % instead of ±15 %
    "noise3mm": {"dropout_rate": 4.0, "noise_std": 3.0},
    "fast": {"dropout_rate": 4.0, "freq_range": (1.5, 2.0)},  # faster than the PoP's movements
}
STRESS = ("fastdrift", "noise3mm", "fast")
FRONT_END_SETS = ("dropouts", "dropouts_nan")  # where the low-pass and the Kalman front ends are compared
# error budget (--sweep only): a pure drifting-free sinusoid, then one ingredient of the model at a time
_PURE = {"noise_std": 0.0, "harmonics": 0.0, "freq_drift": 0.0, "amplitude_drift": 0.0, "offset_drift": 0.0}
BUDGET = {
    "pure": {},
    "noise": {"noise_std": 1.0},
    "harmonics": {"harmonics": 0.08},
    "freq_drift": {"freq_drift": 0.15},
    "amplitude_drift": {"amplitude_drift": 0.15},
    "offset_drift": {"offset_drift": 20.0},
    "all_but_harmonics": {"noise_std": 1.0, "freq_drift": 0.15, "amplitude_drift": 0.15, "offset_drift": 20.0},
}


def signals(n: int, dataset: str) -> list[Oscillation]:
    """``n`` seeded signals; the same seed gives the same drop-out-free signal in every data set."""
    return [generate_oscillation(DURATION, dt=DT, seed=seed, **DATASETS[dataset]) for seed in range(n)]


class FixedWindow(Algorithm1Phase):
    """Algorithm 1 centred by a running mean over a fixed number of seconds, for comparison."""

    def __init__(self, seconds: float, **params: Any) -> None:
        super().__init__(**params)
        self.seconds = seconds

    def _window(self, n_pushed: int) -> int:
        return max(1, min(n_pushed, round(self.seconds / self.dt)))


def estimate(position: np.ndarray, fixed_window: float | None = None, **params: Any) -> np.ndarray:
    """Online phase of one position signal (centred over ``fixed_window`` seconds if given)."""
    estimator = PhaseEstimator(**params)
    if fixed_window is not None:
        estimator.replace("algorithm", FixedWindow(fixed_window, cutoff=estimator["lowpass"].cutoff))
    sim = Simulator(estimator, DT, probes={"theta": "algorithm.theta"})
    return sim.run(n_steps=len(position), inputs={"p": position})["theta"]


def _kept(osc: Oscillation) -> np.ndarray:
    """Mask of the samples more than ``EDGE`` seconds from either end."""
    return (osc.t >= EDGE) & (osc.t <= osc.t[-1] - EDGE)


def errors(oscs: list[Oscillation], **params: Any) -> dict[str, np.ndarray]:
    """Pooled absolute circular errors of the online phase against the Hilbert and the true phase."""
    out: dict[str, list[np.ndarray]] = {"hilbert": [], "true": [], "hilbert_vs_true": []}
    for osc in oscs:
        theta = estimate(osc.position, **params)
        ref = hilbert_phase(osc.clean, dt=osc.dt, highpass=HILBERT_HIGHPASS)
        keep = _kept(osc)
        out["hilbert"].append(np.abs(wrap_pi(theta - ref))[keep])
        out["true"].append(np.abs(wrap_pi(theta - osc.phase))[keep])
        out["hilbert_vs_true"].append(np.abs(wrap_pi(ref - osc.phase))[keep])
    return {name: np.concatenate(parts) for name, parts in out.items()}


def _records(name: str, errs: dict[str, np.ndarray], **context: Any) -> Iterator[dict[str, Any]]:
    for ref in ("hilbert", "true"):
        e = errs[ref]
        for stat, value in (("mean", e.mean()), ("p95", np.percentile(e, 95))):
            yield {
                "name": f"phase1d.{name}.{ref}.{stat}",
                "value": round(float(value), 4),
                "unit": "rad",
                "reference": None,
                "ratio": None,
                **context,
            }


def _front_end_records(
    tag: str, lowpass: dict[str, np.ndarray], kalman: dict[str, np.ndarray], **context: Any
) -> Iterator[dict[str, Any]]:
    """The low-pass and the Kalman front end on the same signals; Kalman's reference is the low-pass figure."""
    for ref in ("hilbert", "true"):
        for stat, f in (("mean", np.mean), ("p95", lambda e: np.percentile(e, 95))):
            low = round(float(f(lowpass[ref])), 4)
            kal = round(float(f(kalman[ref])), 4)
            base = {"unit": "rad", **context}
            yield {
                "name": f"phase1d.front_end.lowpass.{tag}.vs_{ref}.{stat}",
                "value": low,
                "reference": None,
                "ratio": None,
                **base,
            }
            yield {
                "name": f"phase1d.front_end.kalman.{tag}.vs_{ref}.{stat}",
                "value": kal,
                "reference": low,
                "ratio": round(kal / low, 3) if low > 0 else None,
                **base,
            }


def run(quick: bool = False, sweep: bool = False) -> Iterator[dict[str, Any]]:
    """Yield the accuracy records of the default estimator (and of the sweep's variants)."""
    n = 4 if quick else 20
    for tag in DATASETS:
        if tag in STRESS and not sweep:
            continue
        oscs = signals(n, tag)
        context = {"signals": n, "seconds": DURATION}
        errs = errors(oscs)
        yield from _records(f"default.{tag}", errs, **context)
        if tag == "clean":
            hvt = errs["hilbert_vs_true"]
            yield {
                "name": "phase1d.hilbert_vs_true.mean",
                "value": round(float(hvt.mean()), 4),
                "unit": "rad",
                "reference": None,
                "ratio": None,
                **context,
            }
        if tag in FRONT_END_SETS:
            yield from _front_end_records(tag, errs, errors(oscs, front_end="kalman"), **context)
        if sweep and tag != "dropouts_nan":
            for variant, params in CUTOFFS if tag in STRESS else SWEEP:
                yield from _records(f"{variant}.{tag}", errors(oscs, **params), **context, params=params)
    if sweep:
        for case, params in BUDGET.items():
            oscs = [
                generate_oscillation(DURATION, dt=DT, seed=seed, dropout_rate=0.0, **{**_PURE, **params})
                for seed in range(n)
            ]
            yield from _records(f"budget.{case}", errors(oscs), signals=n, seconds=DURATION, generator=params)


def plot(path: str, seeds: tuple[int, ...] = (2, 3)) -> None:
    """Figure: signals with drop-outs (one column per seed), the online and Hilbert phases, and the errors.

    Seed 2 is a typical signal of the ``dropouts`` set (its mean error is the median of the 20);
    seed 3 is the worst, with the strongest harmonics and the lowest frequency.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, len(seeds), figsize=(6 * len(seeds), 7), sharex=True, squeeze=False)
    for col, seed in enumerate(seeds):
        osc = generate_oscillation(DURATION, dt=DT, seed=seed, **DATASETS["dropouts"])
        theta = estimate(osc.position)
        ref = hilbert_phase(osc.clean, dt=DT, highpass=HILBERT_HIGHPASS)
        window = (osc.t >= 20.0) & (osc.t < 32.0)
        t = osc.t[window]
        ax = axes[:, col]
        ax[0].plot(t, osc.position[window], lw=1, label="measured position")
        ax[0].plot(t, np.where(osc.dropout[window], osc.position[window], np.nan), color="red", lw=3, label="drop-out")
        ax[0].set_title(f"seed {seed}")
        ax[1].plot(t, ref[window], lw=1, label="Hilbert (offline)")
        ax[1].plot(t, theta[window], lw=1, ls="--", label="online (Algorithm 1)")
        ax[2].plot(t, wrap_pi(theta - ref)[window], lw=1, label="online − Hilbert")
        ax[2].plot(t, wrap_pi(theta - osc.phase)[window], lw=1, label="online − true")
        ax[2].set_xlabel("time [s]")
        for a, label in zip(ax, ("position [mm]", "phase [rad]", "error [rad]"), strict=True):
            a.set_ylabel(label)
            a.legend(loc="upper right", fontsize=7)
    fig.suptitle("PhaseEstimator with its defaults on synthetic signals with drop-outs")
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="4 signals instead of 20")
    parser.add_argument("--sweep", action="store_true", help="also measure the cut-off and parameter variants")
    parser.add_argument("--plot", metavar="PNG", help="save the example figure to this path")
    args = parser.parse_args(argv)
    for record in run(quick=args.quick, sweep=args.sweep):
        print(json.dumps(record), flush=True)
    if args.plot:
        plot(args.plot)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
