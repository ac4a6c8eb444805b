"""Many groups of the PoP of Social Connectedness in one compiled diagram: the closed loop of
:func:`~cogblocks.diagrams.sync.pop_sync` on a batch, one run per group.

Groups batch together when one diagram can hold them: the same number of participants, assisted
participant, graph and noise model (:func:`batch_key`); frequencies, gains, noise seeds and
durations may differ (a shorter run's figures are taken over its own samples). The motion
computers of :data:`BATCHED_MOTIONS` run the batch in one call; ``dqn_raw`` also needs the
groups' gains and frequencies equal, since its oscillator is built from them. Every figure is that
of the group's own run of :func:`~cogblocks.diagrams.sync.run_sync`, bit for bit (the order
parameter to an ulp).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from cogblocks.blocks.angles import wrap_pi
from cogblocks.data.groups import SyncGroup
from cogblocks.diagrams.naturalness import sync_naturalness
from cogblocks.diagrams.sync import DEFAULT_BLENDER, pop_sync
from cogblocks.sim import BASE_STEP, Diagram, Simulator, Trace
from cogblocks.sync import KuramotoGroup

__all__ = ["BATCHED_MOTIONS", "batch_key", "batches", "pop_sync_batch", "sync_rows"]

#: Motion computers (names of ``MOTIONS``) whose blocks run a batch at once.
BATCHED_MOTIONS = ("mean", "dqn_raw")

_PROBES = {"theta_l2": "l2.theta_l2", "theta_l0": "l2.theta_l0", "theta": "group.theta"}


def batch_key(group: SyncGroup, motion: str | None = "mean") -> tuple:
    """What groups must share to run in one batch with ``motion`` (``None``: without L2)."""
    noise = None if group.noise is None else (group.noise.sigma, group.noise.drift_spread, group.noise.drift_tau)
    graph = group.graph if isinstance(group.graph, (str, tuple)) else np.asarray(group.graph).tobytes()
    key = (group.n, group.assisted, graph, noise)
    return key + ((group.gain, tuple(group.omega)) if motion not in (None, "mean") else ())


def batches(groups: Sequence[SyncGroup], motion: str | None = "mean") -> list[list[int]]:
    """The indices of ``groups`` grouped by :func:`batch_key`, in order of first appearance."""
    found: dict[tuple, list[int]] = {}
    for i, group in enumerate(groups):
        found.setdefault(batch_key(group, motion), []).append(i)
    return list(found.values())


def pop_sync_batch(
    groups: Sequence[SyncGroup], l2: bool = True, motion: str = "mean", blender: Any = DEFAULT_BLENDER
) -> Diagram:
    """One :func:`pop_sync` diagram whose plant holds one run per group (compile it with ``batch=len(groups)``).

    Raises
    ------
    ValueError
        If the groups do not share a :func:`batch_key`, or ``motion`` is not one of :data:`BATCHED_MOTIONS`.
    """
    if l2 and motion not in BATCHED_MOTIONS:
        raise ValueError(f"pop_sync_batch: motion must be one of {BATCHED_MOTIONS}, got {motion!r}")
    keys = {batch_key(g, motion if l2 else None) for g in groups}
    if len(keys) != 1:
        raise ValueError(
            "pop_sync_batch: the groups must share their size, assisted participant, graph and noise model "
            f"(and for {motion!r} also gain and frequencies); got {len(keys)} kinds, split them with batches()"
        )
    base = groups[0]
    diagram = pop_sync(base, l2=l2, motion=motion, blender=blender)
    options = base.plant_options()
    if options:
        options["seed"] = [g.noise.seed for g in groups]
    plant = KuramotoGroup(
        np.array([g.omega for g in groups], dtype=float),
        np.array([g.gain for g in groups], dtype=float),
        adjacency=base.graph,
        assisted=base.assisted if l2 else None,
        **options,
    )
    diagram.replace("group", plant)
    return diagram


def _runs(trace: Trace, lengths: list[int]) -> list[Trace]:
    """Each run of a batched trace, cut to its own number of samples."""
    return [Trace(trace.t[:n], {k: v[:n] for k, v in trace.run(b).items()}, trace.units) for b, n in enumerate(lengths)]


def _simulate(groups: Sequence[SyncGroup], l2: bool, motion: str, blender: Any) -> list[Trace]:
    lengths = [round(g.duration / BASE_STEP) + 1 for g in groups]
    diagram = pop_sync_batch(groups, l2=l2, motion=motion, blender=blender)
    sim = Simulator(diagram, probes=_PROBES if l2 else None, batch=len(groups), progress=False)
    return _runs(sim.run(n_steps=max(lengths)), lengths)


def sync_rows(
    groups: Sequence[SyncGroup], motions: Sequence[str], blender: Any = DEFAULT_BLENDER
) -> list[dict[str, Any]]:
    """:func:`~cogblocks.diagrams.sync.run_sync`'s figures (phase domain) of every group, computed in batches.

    Returns one ``{"r_without", "results": [row per motion]}`` per group, in order, each row as in
    :func:`~cogblocks.diagrams.sync.sync_table`.
    """
    unknown = [m for m in motions if m not in BATCHED_MOTIONS]
    if unknown:
        raise ValueError(f"sync_rows: {unknown} do not run batched; batched motion computers: {BATCHED_MOTIONS}")
    out: list[dict[str, Any]] = [{"results": []} for _ in groups]
    for indices in batches(groups, None):
        traces = _simulate([groups[i] for i in indices], False, "mean", blender)
        for i, trace in zip(indices, traces, strict=True):
            out[i]["r_without"] = float(trace["r"].mean())
    for motion in motions:
        for indices in batches(groups, motion):
            traces = _simulate([groups[i] for i in indices], True, motion, blender)
            for i, trace in zip(indices, traces, strict=True):
                r_with, r_without = float(trace["r"].mean()), out[i]["r_without"]
                dev = np.abs(wrap_pi(trace["theta_l2"] - trace["theta_l0"]))
                out[i]["results"].append(
                    {
                        "policy": motion,
                        "r_with": r_with,
                        "change_pct": 100.0 * (r_with - r_without) / r_without,
                        "mean_dev_rad": float(dev.mean()),
                        "max_dev_rad": float(dev.max()),
                        **sync_naturalness(trace, None),
                    }
                )
    return out
