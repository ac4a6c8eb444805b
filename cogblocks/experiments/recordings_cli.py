"""Command-line parts for recordings: ``cogblocks analyse group FILE`` and ``cogblocks run phase3d --recording``."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from typing import Any

import numpy as np

from cogblocks.cli_options import COUNT, PLOT_PATH, SEED, STEP
from cogblocks.sim.timing import BASE_STEP

__all__ = ["add_analyse_parser", "add_recording_options", "plot_group"]


def add_recording_options(phase3d: argparse.ArgumentParser, synthetic: Callable[[argparse.Namespace], int]) -> None:
    """``--recording FILE --marker NAME`` on ``cogblocks run phase3d``; without them ``synthetic`` runs."""
    phase3d.add_argument("--recording", metavar="FILE", help="run on a recorded marker (.c3d or .xdf) instead")
    phase3d.add_argument("--marker", metavar="NAME", help="with --recording: the marker (the assisted person)")

    def handler(args: argparse.Namespace) -> int:
        if args.recording is None:
            if args.marker is not None:
                raise ValueError("--marker names a marker of --recording FILE: give --recording too")
            return synthetic(args)
        return _run_phase3d_recording(args)

    phase3d.set_defaults(handler=handler)


def _run_phase3d_recording(args: argparse.Namespace) -> int:
    from cogblocks.diagrams.recording import phase3d_recording, plot_phase3d_recording

    if args.marker is None:
        raise ValueError("--recording needs --marker NAME (the marker whose phase is estimated)")
    if (args.trajectories, args.seed, args.rate, args.motion_set) != (30, 0, 100.0, "today"):
        raise ValueError("--recording runs on the file: drop --trajectories, --seed, --rate and --set")
    r = phase3d_recording(args.recording, args.marker)
    chain = r["chain"]
    text = (
        f"3D phase of marker {r['marker']!r} in {r['file']} ({r['duration_s']:.1f} s on a {1000 * r['dt']:g} ms grid, "
        f"{100 * r['gap_share']:.1f} % gaps), reference: the recording's mean cycle\n"
        f"  online vs offline PCA-Hilbert: mean {r['mean_error_vs_offline_rad']:.3f} rad, "
        f"95th percentile {r['p95_error_vs_offline_rad']:.3f} rad (valid on {100 * r['valid_share']:.1f} % of ticks)\n"
        f"phase chain (the recorded person → phase → L2 → 3D avatar, group 3): r {chain['r_mean']:.3f}, "
        f"|θ_L2 − θ_L0| mean {chain['mean_dev_rad']:.3f} rad, valid from {chain['valid_from_s']:.2f} s"
    )
    print(json.dumps(r) if args.json else text, flush=True)
    if args.plot:
        plot_phase3d_recording(args.recording, args.marker, args.plot)
        print(f"wrote {args.plot}", file=sys.stderr, flush=True)
    return 0


def add_analyse_parser(commands: Any) -> None:
    """``cogblocks analyse group FILE --markers A,B,C``."""
    analyse = commands.add_parser("analyse", help="analyse a recorded session")
    kinds = analyse.add_subparsers(dest="kind", metavar="KIND")
    analyse.set_defaults(handler=lambda _: analyse.print_help() or 2)
    group = kinds.add_parser(
        "group", help="phases, r(t) and a surrogate test of a recorded group (.c3d or .xdf, one marker per person)"
    )
    group.add_argument("file", metavar="FILE", help="the recording (.c3d or .xdf)")
    group.add_argument("--markers", required=True, type=_names, metavar="A,B,...", help="one marker per participant")
    group.add_argument("--surrogates", type=COUNT, default=199, metavar="N", help="time-shift surrogates (def. 199)")
    group.add_argument("--seed", type=SEED, default=0, help="seed of the surrogates (default 0)")
    group.add_argument(
        "--dt", type=STEP, default=BASE_STEP, metavar="SECONDS", help=f"grid step (default {BASE_STEP:g})"
    )
    group.add_argument("--unit", metavar="UNIT", help="length unit (m, cm, mm) of XDF channels that declare none")
    group.add_argument("--offline-only", action="store_true", help="skip the online estimator (faster)")
    group.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    group.add_argument("--plot", type=PLOT_PATH, metavar="FILE", help="after the results, save r(t) and the test")
    group.set_defaults(handler=_run_analyse_group)


def _names(text: str) -> list[str]:
    names = [name.strip() for name in text.split(",")]
    if len(names) < 2 or not all(names) or len(set(names)) != len(names):
        raise argparse.ArgumentTypeError(f"expected at least 2 distinct marker names separated by commas, got {text!r}")
    return names


def _run_analyse_group(args: argparse.Namespace) -> int:
    from cogblocks.data.recordings import load_recording
    from cogblocks.experiments.group_analysis import analyse_group

    if args.surrogates < 19:
        raise ValueError(f"--surrogates must be at least 19 (for a p-value that can reach 0.05), got {args.surrogates}")
    recording = load_recording(args.file, args.markers, dt=args.dt, unit=args.unit)
    result = analyse_group(
        recording, args.markers, dt=args.dt, online=not args.offline_only, n_surrogates=args.surrogates, seed=args.seed
    )
    series = result.pop("series")
    nulls = {"offline": result["offline"].pop("null")}
    if result["online"] is not None:
        nulls["online"] = result["online"].pop("null")
    for entry in result["conditions"].values():
        if entry["offline"] is not None:
            entry["offline"].pop("null")
    print(json.dumps(result) if args.json else _render(result), flush=True)
    if args.plot:
        plot_group(result, series, nulls, args.plot)
        print(f"wrote {args.plot}", file=sys.stderr, flush=True)
    return 0


def _line(name: str, test: dict[str, Any]) -> str:
    verdict = "above chance" if test["above_chance"] else "not above chance"
    return (
        f"  {name:>8}: time-averaged r {test['r_mean']:.3f}; surrogates mean {test['null_mean']:.3f}, "
        f"95th percentile {test['null_p95']:.3f}; p = {test['p_value']:.3g} ({verdict})"
    )


def _render(r: dict[str, Any]) -> str:
    lines = [
        f"{len(r['markers'])} participants ({', '.join(r['markers'])}) in {r['file']}, {r['duration_s']:.1f} s; "
        f"synchronisation against {r['offline']['n_surrogates']} time-shifted surrogates:",
        _line("offline", r["offline"]),
    ]
    if r["online"] is not None:
        lines.append(
            _line("online", r["online"]) + f"; online vs offline {r['online']['mean_error_vs_offline_rad']:.3f} rad"
        )
    for label, entry in r["conditions"].items():
        if entry["offline"] is None:
            lines.append(f"  condition {label!r} ({entry['duration_s']:.1f} s): {entry['note']}")
        else:
            lines.append(
                f"  condition {label!r} ({entry['duration_s']:.1f} s):\n  " + _line("offline", entry["offline"])
            )
    return "\n".join(lines)


def plot_group(result: dict[str, Any], series: dict[str, np.ndarray], nulls: dict[str, np.ndarray], path: str) -> None:
    """r(t) (offline and online) and the surrogates' distribution against the observed time average."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 3.8), gridspec_kw={"width_ratios": [2, 1]})
    left.plot(series["t"], series["r_offline"], lw=1.0, label="offline (PCA + Hilbert)")
    if result["online"] is not None:
        left.plot(series["t"], series["r_online"], lw=1.0, ls="--", label="online")
    left.set_xlabel("t [s]")
    left.set_ylabel("r(t)")
    left.set_ylim(0.0, 1.02)
    left.legend(loc="lower right", fontsize=8)
    for k, (name, null) in enumerate(nulls.items()):
        colour = f"C{k}"
        right.hist(null, bins=30, alpha=0.5, color=colour, label=f"surrogates ({name})")
        observed = f"observed ({name}), p = {result[name]['p_value']:.3g}"
        right.axvline(result[name]["r_mean"], lw=1.5, color=colour, ls="-" if k == 0 else "--", label=observed)
    right.set_xlabel("time-averaged r")
    right.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
