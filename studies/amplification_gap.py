"""Planned against emitted: how far the optimised blender's last plan is from the movement it emits.

Usage::

    python -m studies.amplification_gap --e-des 0 --limit 30 [--emit human|plan|tail] [--track-past 0|1]

Each plan is checked on the movement the block *would* emit if the human followed the prediction (the
emitted past, then the plan in force). On the inner split
(:func:`~studies.amplification_inner.inner_setup`, the blender as :data:`OPTIMISED`), this
replays the first ``limit`` inner movements and compares, per movement, that checked movement of the last
committed plan with the movement actually emitted: the constrained networks' ε̂ on both, the judges'
decisions on both and the six kinematic features of both; and, over every committed plan, how many fail
their own encoding constraint when committed (the least favourable constrained network's ε̂ of the check at
the commit, on the past actually emitted, not beyond the clipping threshold). Prints one JSON line
(``--per-movement`` adds every movement's row).
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch

from cogblocks.amplification import OptimalBlender
from cogblocks.amplification.emission import EMISSIONS
from cogblocks.amplification.judges import FEATURES, kinematic_features
from cogblocks.diagrams.amplification import replay_movement
from cogblocks.diagrams.amplification_setup import (
    OPTIMISED,
    AmplificationSetup,
    amplification_judges,
    blender_networks,
)
from studies.amplification_inner import inner_setup

__all__ = ["RecordingBlender", "main", "planned_vs_emitted", "summarise"]


class RecordingBlender(OptimalBlender):
    """An :class:`OptimalBlender` that keeps, for every decision, the movement its outcome check classified.

    ``checked[i]`` is the padded velocity (T, 3) behind ``results[i].eps``: the emitted past, then the
    state in force after the decision, on the decision's prediction.
    """

    def reset(self) -> None:
        super().reset()
        self.checked: list[np.ndarray] = []

    def _outcome(self, t: int, predicted: np.ndarray, state: dict[str, Any]) -> tuple[float, float]:
        self.checked.append(self._emission(t, predicted, state))
        return super()._outcome(t, predicted, state)


def planned_vs_emitted(setup: AmplificationSetup, limit: int, **options: Any) -> list[dict[str, Any]]:
    """One row per replayed movement: the last committed plan's checked movement against the emitted one.

    ``options`` are the blender's keyword arguments on top of :data:`OPTIMISED` (without ``components``).
    A movement without a committed plan has ``planned`` None.
    """
    networks = blender_networks(setup.encoder)
    settings = {k: v for k, v in OPTIMISED.items() if k != "components"} | options
    judges = amplification_judges()
    rows = []
    for index in setup.humans[:limit]:
        blender = RecordingBlender(
            setup.movements, networks, setup.table, e_des=setup.e_des, subspace=setup.subspace, **settings
        )
        trace = replay_movement(setup, int(index), blender)
        emitted = np.asarray(trace["v_a"], dtype=np.float64)
        committed = [i for i, r in enumerate(blender.results) if r.status in ("converged", "accepted")]
        failing = [i for i in committed if not _clipped(blender.results[i].eps, setup.e_des)]
        planned = blender.checked[committed[-1]] if committed else None
        movements = np.stack([emitted, emitted if planned is None else planned])
        decisions = judges.decide(movements)
        features = kinematic_features(movements, setup.library.dt)
        rows.append({
            "index": int(index),
            "planned": None if planned is None else {
                "members": blender.member_eps(planned).tolist(), "ensemble": int(decisions["ensemble"][1]),
                "kinematic": int(decisions["kinematic"][1]), "features": features[1].tolist(),
                "max_abs_diff": float(np.abs(planned - emitted).max()),
            },
            "emitted": {
                "members": blender.member_eps(emitted).tolist(), "ensemble": int(decisions["ensemble"][0]),
                "kinematic": int(decisions["kinematic"][0]), "features": features[0].tolist(),
            },
            "last_commit_tick": int(blender.results[committed[-1]].tick) if committed else None,
            "committed": len(committed),
            "failing_at_commit": len(failing),
            "guarded_ticks": len(blender.guarded_ticks),
        })  # fmt: skip
    return rows


def _clipped(eps: float, e_des: int) -> bool:
    """Whether ``eps`` decides ``e_des`` by the clipping rule (ε̂ > 0.9, or < 0.1)."""
    return bool(eps > 0.9) if e_des else bool(eps < 0.1)


def summarise(rows: list[dict[str, Any]], e_des: int) -> dict[str, Any]:
    """Shares decided as ``e_des`` on the planned and on the emitted movements, and the features' differences.

    ``all_members``: every constrained network decides ``e_des`` by the clipping rule (ε̂ > 0.9, < 0.1);
    ``flipped``: movements on which they do for the plan but not for the emitted movement.
    ``feature_abs_diff``: per feature, the median and the 90th percentile of ``|emitted − planned|``.
    ``committed``, ``failing_at_commit``: committed plans in all, and those failing their encoding constraint
    at the commit (rows without these counts are left out of them).
    """
    planned = [r for r in rows if r["planned"] is not None]

    def decides(eps: list[float]) -> bool:
        return all(_clipped(e, e_des) for e in eps)

    out: dict[str, Any] = {"n": len(rows), "with_plan": len(planned)}
    for side in ("planned", "emitted"):
        out[side] = {
            "all_members": float(np.mean([decides(r[side]["members"]) for r in planned])),
            "ensemble_judge": float(np.mean([r[side]["ensemble"] == e_des for r in planned])),
            "kinematic_judge": float(np.mean([r[side]["kinematic"] == e_des for r in planned])),
        }
    out["flipped"] = int(
        sum(decides(r["planned"]["members"]) and not decides(r["emitted"]["members"]) for r in planned)
    )
    diff = np.array([np.subtract(r["emitted"]["features"], r["planned"]["features"]) for r in planned])
    out["feature_abs_diff"] = {
        name: {"p50": float(np.median(np.abs(diff[:, j]))), "p90": float(np.percentile(np.abs(diff[:, j]), 90))}
        for j, name in enumerate(FEATURES)
    }
    out["velocity_max_abs_diff_p50"] = float(np.median([r["planned"]["max_abs_diff"] for r in planned]))
    out["guarded_ticks"] = int(sum(r["guarded_ticks"] for r in rows))
    out["committed"] = int(sum(r.get("committed", 0) for r in rows))
    out["failing_at_commit"] = int(sum(r.get("failing_at_commit", 0) for r in rows))
    return out


def main(argv: Sequence[str] | None = None) -> int:
    """Command-line entry point: print the summary (and with ``--per-movement`` the rows) as JSON."""
    parser = argparse.ArgumentParser(prog="python -m studies.amplification_gap", description=__doc__)
    parser.add_argument("--e-des", type=int, choices=(0, 1), default=0)
    parser.add_argument("--limit", type=int, default=30, help="inner movements replayed (default 30)")
    parser.add_argument("--emit", choices=EMISSIONS, default=OPTIMISED.get("emit", "human"))
    parser.add_argument("--track-past", type=int, choices=(0, 1), default=int(OPTIMISED.get("track_past", False)))
    parser.add_argument("--per-movement", action="store_true", help="print every movement's row too")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    options = {"emit": args.emit, "track_past": bool(args.track_past)}
    rows = planned_vs_emitted(inner_setup(args.e_des), args.limit, **options)
    out = {"e_des": args.e_des, "limit": args.limit, **options, **summarise(rows, args.e_des)}
    if args.per_movement:
        out["rows"] = rows
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
