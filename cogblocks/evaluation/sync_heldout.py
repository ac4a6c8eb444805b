"""Held-out evaluation of the L3 policies of the PoP of Social Connectedness on random groups.

Every policy of :data:`cogblocks.diagrams.sync.MOTIONS` runs, in the closed-loop diagram of
:func:`~cogblocks.diagrams.sync.pop_sync`, on the first groups of the *test* split of
:func:`~cogblocks.data.groups.random_groups`; each group is compared with itself without L2 and
with :func:`~cogblocks.evaluation.sync_bound.upper_bound` (whole-run optimal control of the alteration, or the
best constant reference frequency where that is higher; without the ``pace`` start, for time).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np

from cogblocks.data.groups import SyncGroup, random_groups
from cogblocks.diagrams.sync import DEFAULT_BLENDER, MOTIONS, run_sync
from cogblocks.evaluation.sync_bound import upper_bound

__all__ = ["evaluate_group", "heldout_table", "plot_heldout", "summarise"]

#: Below this headroom (bound minus r without L2; r is in [0, 1]) a group's fraction of the bound is left
#: out of the mean: a tiny denominator would let one group dominate it.
MIN_HEADROOM = 1e-3


def evaluate_group(
    group: SyncGroup,
    policies: list[str],
    bound: bool = True,
    thorough: bool = False,
    domain: str = "phase",
    blender: str = DEFAULT_BLENDER,
    done: dict[str, Any] | None = None,
    handover: bool = True,
) -> dict[str, Any]:
    """One group: r without L2, the bound, and per policy r with L2, the change and the deviations.

    ``done`` holds figures already computed (a row of :func:`~cogblocks.diagrams.sync_batch.sync_rows`,
    from a batch): its policies are not run again.

    Returns
    -------
    dict
        ``{"name", "n", "graph", "r_without", "r_bound", "results": [...]}`` where ``results`` are
        :func:`run_sync`'s rows plus ``bound_fraction = (r_with − r_without) / (r_bound − r_without)``
        (``None`` without headroom, and ``r_bound`` and every fraction ``None`` with ``bound=False``).
        ``thorough`` computes the thorough bound (``upper_bound(thorough=True)``, about 3× the CPU). A noisy
        group's row also holds ``"noise"`` (:meth:`~cogblocks.data.groups.GroupNoise.as_dict`), and its bound is
        the clairvoyant one (the noise draw known). ``domain="position"`` runs the policies on phases estimated
        from arm positions (the bound stays the phase domain's), with :func:`pop_sync`'s ``handover``.
    """
    ready = {row["policy"]: row for row in (done or {}).get("results", [])}
    result = run_sync(group, [p for p in policies if p not in ready], domain, blender=blender, handover=handover)
    if done is not None:
        computed = {row["policy"]: row for row in result["results"]}
        result = {"r_without": done["r_without"], "results": [ready.get(p) or computed[p] for p in policies]}
    r_without = result["r_without"]
    # without the pace start unless thorough: it would cost as much again
    r_bound = upper_bound(group, pace=False, thorough=thorough) if bound else None
    headroom = -math.inf if r_bound is None else r_bound - r_without
    for row in result["results"]:
        row["bound_fraction"] = (row["r_with"] - r_without) / headroom if headroom > MIN_HEADROOM else None
    row = {
        "name": group.name,
        "n": group.n,
        "graph": group.graph_kind,
        "r_without": r_without,
        "r_bound": r_bound,
        "results": result["results"],
    }
    if group.noise is not None:
        row["noise"] = group.noise.as_dict()
    return row


def summarise(rows: list[dict[str, Any]], policies: list[str]) -> list[dict[str, Any]]:
    """Per policy: share of groups lowered, mean / 5th percentile / worst change (%), bound fraction, deviations.

    Naturalness over the groups (:mod:`cogblocks.diagrams.naturalness`): ``max_step_rad`` (the largest per-tick
    change of wrap(θ_L2 − θ_L0) on any group), ``mean_jumps_per_min``, ``jump_free_share`` (share of groups
    without a jump) and ``max_peak_speed_ratio`` (the largest of the groups' peak phase speed ratios). A motion
    computer that reports its world (:class:`~cogblocks.sync.GatedMotion`) adds ``noisy_share``, the share of
    groups it found noisy.
    """
    summary = []
    for policy in policies:
        results = [next(r for r in row["results"] if r["policy"] == policy) for row in rows]
        change = np.array([r["change_pct"] for r in results])
        fractions = [r["bound_fraction"] for r in results if r["bound_fraction"] is not None]
        summary.append(
            {
                "policy": policy,
                "lowered_share": float(np.mean(change < 0.0)),
                "mean_change_pct": float(change.mean()),
                "p5_change_pct": float(np.percentile(change, 5)),
                "worst_change_pct": float(change.min()),
                "mean_bound_fraction": float(np.mean(fractions)) if fractions else None,
                "mean_dev_rad": float(np.mean([r["mean_dev_rad"] for r in results])),
                "max_dev_rad": float(np.max([r["max_dev_rad"] for r in results])),
                **_naturalness_summary(results),
            }
        )
        worlds = [r["world"] for r in results if "world" in r]
        if worlds:  # a motion computer that says which world it found (GatedMotion): how often it found noise
            summary[-1]["noisy_share"] = float(np.mean([w == "noisy" for w in worlds]))
    return summary


def _naturalness_summary(results: list[dict[str, Any]]) -> dict[str, float]:
    jumps = np.array([r["jumps_per_min"] for r in results])
    return {
        "max_step_rad": float(np.max([r["max_step_rad"] for r in results])),
        "mean_jumps_per_min": float(jumps.mean()),
        "jump_free_share": float(np.mean(jumps == 0.0)),
        "max_peak_speed_ratio": float(np.max([r["peak_speed_ratio"] for r in results])),
    }


def heldout_table(
    n_groups: int,
    seed: int = 0,
    policies: list[str] | None = None,
    *,
    workers: int = 1,
    details: bool = False,
    groups: list[SyncGroup] | None = None,
    max_duration: float | None = None,
    split: str = "test",
    bound: bool = True,
    thorough: bool = False,
    noise: bool = False,
    domain: str = "phase",
    handover: bool = True,
    blender: str = DEFAULT_BLENDER,
    batch: bool = False,
    progress: Callable[[int, dict[str, Any]], None] | None = None,
) -> dict[str, Any]:
    """Evaluate ``policies`` (all of :data:`MOTIONS` by default) on ``n_groups`` groups of ``split`` and ``seed``.

    Parameters
    ----------
    n_groups : int
        How many groups of the split, >= 1.
    seed : int
        Seed of :func:`random_groups`.
    policies : list of str, optional
        Names from :data:`MOTIONS`.
    workers : int
        Processes running groups in parallel (joblib's loky backend); 1 runs them here.
    details : bool
        Also return every group's row under ``"groups"``.
    groups : list of SyncGroup, optional
        Evaluate these instead of the test split (``seed`` is then only reported).
    max_duration : float, optional
        Cut every group's duration to at most this many seconds (a quick look; not the held-out table).
    split : {"test", "validation", "train"}
        The split of :func:`random_groups`: ``"test"`` for the held-out table, ``"validation"`` to choose a
        policy or its settings without looking at the test split.
    bound : bool
        Compute the bound (its fractions are ``None`` without it; it costs about 17 s of CPU per 100 s group).
    thorough : bool
        The thorough bound instead (:func:`~cogblocks.evaluation.sync_bound.upper_bound` with ``thorough=True``):
        the ``pace`` and default policies' references as starts and four sweeps, about 3× the CPU.
    noise : bool
        Noisy groups (``random_groups(..., noise=True)``: phase noise and frequency drift, the same draw with and
        without L2); the bound is then the clairvoyant one.
    domain : {"phase", "position"}
        Where the policies read the phases (see :func:`~cogblocks.diagrams.sync.pop_sync`).
    handover : bool
        In the position domain, :func:`~cogblocks.diagrams.sync.pop_sync`'s ``handover``.
    blender : {"continuous", "deliverable"}
        The blender of every closed loop (:func:`~cogblocks.diagrams.sync.pop_sync`'s); the bound is the deliverable's.
    batch : bool
        Run the policies that batch (:data:`~cogblocks.diagrams.sync_batch.BATCHED_MOTIONS`) and the runs
        without L2 on batched diagrams, the groups that share a structure together (phase domain; the same
        figures, bit for bit); the other policies and the bounds run group by group.
    progress : callable, optional
        ``progress(index, row)`` as each group is done (with workers, in the order they finish), ``row`` as
        :func:`evaluate_group` returns it: an interrupted caller keeps every group finished so far.

    Returns
    -------
    dict
        ``{"n_groups", "seed", "policies": [summary per policy]}`` (see :func:`summarise`); with noisy groups
        also ``"domain"`` and ``"noise"``, each group's noise parameters in order.
    """
    policies = list(MOTIONS) if policies is None else list(policies)
    unknown = [name for name in policies if name not in MOTIONS]
    if unknown:
        raise ValueError(f"unknown policy {unknown[0]!r}: choose from {sorted(MOTIONS)}")
    if workers < 1:
        raise ValueError(f"workers must be at least 1, got {workers}")
    if groups is None:
        if n_groups < 1:
            raise ValueError(f"the number of random groups must be at least 1, got {n_groups}")
        groups = random_groups(n_groups, split, seed, noise=noise)
    if max_duration is not None:
        if not max_duration > 0:
            raise ValueError(f"max_duration must be positive, got {max_duration}")
        groups = [dataclasses.replace(g, duration=min(g.duration, max_duration)) for g in groups]
    ready: list[Any] = [None] * len(groups)  # figures computed on batched diagrams
    if batch and domain == "phase":
        from cogblocks.diagrams.sync_batch import BATCHED_MOTIONS, sync_rows

        ready = sync_rows(groups, [p for p in policies if p in BATCHED_MOTIONS], blender)
    calls = [(g, policies, bound, thorough, domain, blender, ready[i], handover) for i, g in enumerate(groups)]
    rows = each_group(evaluate_group, calls, workers, progress)
    table: dict[str, Any] = {"n_groups": len(groups), "seed": seed, "policies": summarise(rows, policies)}
    if any(group.noise is not None for group in groups):
        table["domain"] = domain
        table["noise"] = [row.get("noise") for row in rows]
    if details:
        table["groups"] = rows
    return table


def each_group(
    evaluate: Callable[..., dict[str, Any]],
    calls: list[tuple],
    workers: int = 1,
    progress: Callable[[int, dict[str, Any]], None] | None = None,
) -> list[dict[str, Any]]:
    """``evaluate(*call)`` for every call (a group's arguments), in order; joblib's loky with ``workers`` > 1.

    ``progress(index, row)`` is called as each row arrives (with workers, in the order they finish), so that an
    interrupted caller keeps every group finished so far.
    """
    if workers == 1:
        done: Iterable[tuple[int, dict[str, Any]]] = ((i, evaluate(*call)) for i, call in enumerate(calls))
    else:
        from joblib import Parallel, delayed

        done = Parallel(n_jobs=workers, backend="loky", return_as="generator_unordered")(
            delayed(_indexed)(evaluate, i, call) for i, call in enumerate(calls)
        )
    by_index: dict[int, dict[str, Any]] = {}
    for index, row in done:
        by_index[index] = row
        if progress is not None:
            progress(index, row)
    return [by_index[i] for i in range(len(calls))]


def _indexed(evaluate: Callable[..., dict[str, Any]], index: int, call: tuple) -> tuple[int, dict[str, Any]]:
    """``evaluate(*call)`` with its index, for results that arrive in the order they finish."""
    return index, evaluate(*call)


def plot_heldout(table: dict[str, Any], path: str) -> None:
    """Save each group's change of r against the bound's change, one panel per policy.

    ``table`` is :func:`heldout_table`'s result with ``details=True``. A point on the diagonal reaches
    the bound; below 0 the policy lowers r. The bound is the best reference found, not a proof: points above
    the diagonal are possible.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = table.get("groups")
    if not rows:
        raise ValueError("plot_heldout needs heldout_table(..., details=True)")
    policies = [p["policy"] for p in table["policies"]]
    bound = np.array([100.0 * (row["r_bound"] - row["r_without"]) / row["r_without"] for row in rows])
    fig, axes = plt.subplots(1, len(policies), figsize=(4.2 * len(policies), 4.0), squeeze=False, sharey=True)
    low, high = min(0.0, bound.min()), max(1.0, bound.max())
    for ax, policy in zip(axes[0], policies, strict=True):
        change = np.array([next(r for r in row["results"] if r["policy"] == policy)["change_pct"] for row in rows])
        lowered = change < 0.0
        diagonal = np.linspace(low, high, 400)  # dense: the x axis is symlog, a two-point line would bend
        ax.plot(diagonal, diagonal, color="0.6", lw=0.8, label="= bound")
        ax.axhline(0.0, color="0.3", lw=0.8)
        ax.scatter(bound[~lowered], change[~lowered], s=9, color="tab:blue", label="raised")
        ax.scatter(bound[lowered], change[lowered], s=12, color="tab:red", label=f"lowered ({lowered.sum()})")
        ax.set_title(f"{policy}: mean {change.mean():+.2f} %, worst {change.min():+.2f} %", fontsize=9)
        ax.set_xlabel("bound's change of r (%)")
        ax.set_xscale("symlog", linthresh=1.0)
        ax.legend(fontsize=7, loc="upper left")
    axes[0][0].set_ylabel("policy's change of r (%)")
    fig.suptitle(f"{table['n_groups']} held-out test groups (seed {table['seed']})", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
