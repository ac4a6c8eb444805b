"""The PoP of Social Connectedness as sweep tasks: Table 2's groups (or held-out random ones) × motion computers.

One task is one closed loop of :func:`~cogblocks.diagrams.sync.pop_sync`, over the group's duration
(samples ``t = 0 … T`` as in :func:`~cogblocks.diagrams.sync.run_sync`); the policy ``"none"`` is
the group without the L2 architecture, the baseline of ``change_pct``.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd

from cogblocks.data import groups as group_data
from cogblocks.data.groups import TABLE2, SyncGroup
from cogblocks.diagrams.sync import DEFAULT_BLENDER, MOTIONS, pop_sync
from cogblocks.diagrams.sync_batch import BATCHED_MOTIONS, sync_rows
from cogblocks.experiments.sweep import sweep, sweep_seeds
from cogblocks.sim import Simulator, Trace

__all__ = ["NO_L2", "random_group_set", "save_sync_trace", "sweep_sync", "sync_measure", "sync_run", "table2_groups"]

#: The policy name of a run without the L2 architecture.
NO_L2 = "none"

_L2_PROBES = {"theta_l2": "l2.theta_l2", "theta_l0": "l2.theta_l0"}


def table2_groups(numbers: Sequence[int] = (1, 2, 3)) -> dict[str, SyncGroup]:
    """Table 2's groups by their number as a string (the label of the sweep's ``group`` column)."""
    unknown = [n for n in numbers if n not in TABLE2]
    if unknown:
        raise ValueError(f"Table 2 has groups {sorted(TABLE2)}, got {unknown}")
    return {str(n): TABLE2[n] for n in numbers}


def random_group_set(n: int, split: str = "test", seed: int = 0) -> dict[str, SyncGroup]:
    """``n`` random groups of ``split`` from ``cogblocks.data.groups.random_groups``, labelled ``<split><i>``."""
    make = getattr(group_data, "random_groups", None)
    if make is None:
        raise ValueError("random groups need cogblocks.data.groups.random_groups")
    return {f"{split}{i}": g for i, g in enumerate(make(n, split=split, seed=seed))}


def _closed_loop(
    group: SyncGroup, policy: str, seed: int, domain: str, blender: str = DEFAULT_BLENDER, handover: bool = True
) -> Simulator:
    if policy == NO_L2:
        return Simulator(pop_sync(group, l2=False), progress=False)
    if policy not in MOTIONS:
        raise ValueError(f"policy must be {NO_L2!r} or one of {sorted(MOTIONS)}, got {policy!r}")
    diagram = pop_sync(group, l2=True, motion=policy, blender=blender, domain=domain, seed=seed, handover=handover)
    return Simulator(diagram, probes=_L2_PROBES, progress=False)


def sync_run(
    group: str,
    policy: str,
    seed: int,
    *,
    groups: Mapping[str, SyncGroup],
    domain: str = "phase",
    blender: str = DEFAULT_BLENDER,
    handover: bool = True,
) -> Callable[[], Trace]:
    """The run function of one task: the closed loop of ``groups[group]`` with ``policy`` behind ``blender``.

    ``seed`` seeds the arm-position noise of the ``"position"`` domain (``handover`` as in ``pop_sync``); the
    phase domain is deterministic.
    """
    params = groups[group]
    sim = _closed_loop(params, policy, seed, domain, blender, handover)
    return functools.partial(sim.run, n_steps=round(params.duration / sim.dt) + 1)


def sync_measure(trace: Trace) -> dict[str, float]:
    """``r_mean`` (time-averaged order parameter) and, with L2, ``|wrap(θ_L2 − θ_L0)|`` mean and max."""
    figures = {"r_mean": float(trace["r"].mean()), "mean_dev_rad": np.nan, "max_dev_rad": np.nan}
    if "theta_l2" in trace:
        dev = np.abs(np.angle(np.exp(1j * (trace["theta_l2"] - trace["theta_l0"]))))
        figures.update(mean_dev_rad=float(dev.mean()), max_dev_rad=float(dev.max()))
    return figures


def sweep_sync(
    groups: Mapping[str, SyncGroup],
    policies: Sequence[str],
    *,
    domain: str = "phase",
    seeds: int = 1,
    backend: str = "loky",
    n_jobs: int | None = None,
    client: Any = None,
    progress: bool | None = None,
    batch: bool = False,
) -> pd.DataFrame:
    """The group comparison as a sweep: every group × (no L2 and every policy) × seed.

    Returns the sweep's DataFrame (see :func:`~cogblocks.experiments.sweep.sweep`) with
    ``change_pct``, the change of ``r_mean`` against the same group and seed without L2. With
    ``batch`` (phase domain), the runs without L2 and the policies that batch
    (:data:`~cogblocks.diagrams.sync_batch.BATCHED_MOTIONS`) run here on batched diagrams, the groups
    that share a structure together (their rows are the same figures; the deviations to rounding).
    """
    names = [NO_L2] + [p for p in policies if p != NO_L2]
    together = [p for p in names if batch and domain == "phase" and (p == NO_L2 or p in BATCHED_MOTIONS)]
    alone = [p for p in names if p not in together]
    frames = [_batched_frame(groups, together, seeds)] if together else []
    if alone:
        frames.append(
            sweep(
                functools.partial(sync_run, groups=dict(groups), domain=domain),
                {"group": list(groups), "policy": alone},
                measure=sync_measure,
                seeds=seeds,
                backend=backend,
                n_jobs=n_jobs,
                client=client,
                progress=progress,
            )
        )
    df = pd.concat(frames, ignore_index=True) if len(frames) > 1 else frames[0]
    order = {g: i for i, g in enumerate(groups)}, {p: i for i, p in enumerate(names)}
    df = df.sort_values(
        ["group", "policy", "replicate"],
        key=lambda c: c.map(order[0]) if c.name == "group" else (c.map(order[1]) if c.name == "policy" else c),
        kind="stable",
    ).reset_index(drop=True)
    baseline = df[df["policy"] == NO_L2].set_index(["group", "seed"])["r_mean"]
    base = baseline.reindex(pd.MultiIndex.from_frame(df[["group", "seed"]])).to_numpy()
    df.insert(df.columns.get_loc("r_mean") + 1, "change_pct", 100.0 * (df["r_mean"].to_numpy() - base) / base)
    return df


def _batched_frame(groups: Mapping[str, SyncGroup], names: Sequence[str], seeds: int | Sequence[int]) -> pd.DataFrame:
    """The sweep's rows of ``names`` (the phase domain: every seed the same run), from batched diagrams."""
    seed_list = sweep_seeds(seeds) if isinstance(seeds, (int, np.integer)) else [int(s) for s in seeds]
    rows = sync_rows(list(groups.values()), [p for p in names if p != NO_L2])
    records = []
    for label, row in zip(groups, rows, strict=True):
        by_policy = {r["policy"]: r for r in row["results"]}
        for policy in names:
            figures = {"r_mean": row["r_without"], "mean_dev_rad": np.nan, "max_dev_rad": np.nan}
            if policy != NO_L2:
                r = by_policy[policy]
                figures = {"r_mean": r["r_with"], "mean_dev_rad": r["mean_dev_rad"], "max_dev_rad": r["max_dev_rad"]}
            for replicate, seed in enumerate(seed_list):
                records.append(
                    {"group": label, "policy": policy, "replicate": replicate, "seed": seed, **figures, "error": None}
                )
    return pd.DataFrame.from_records(records)


def save_sync_trace(group: int, policy: str, domain: str, path: str, *, blender: str = DEFAULT_BLENDER) -> None:
    """Write the trace of one closed loop of Table 2's ``group`` with ``policy`` (``run sync --save-trace``)."""
    sync_trace(group, policy, domain, blender=blender).save(path)


def sync_trace(group: int, policy: str, domain: str, *, blender: str = DEFAULT_BLENDER, handover: bool = True) -> Trace:
    """The trace of one closed loop of Table 2's ``group`` with ``policy``."""
    groups = table2_groups([group])
    return sync_run(str(group), policy, 0, groups=groups, domain=domain, blender=blender, handover=handover)()
