"""The held-out table: every group handed to ``progress`` as it is done, in the groups' order; a motion computer
that says which world it found is counted."""

from __future__ import annotations

import dataclasses

import pytest

from cogblocks.data.groups import TABLE2, GroupNoise, SyncGroup, random_groups
from cogblocks.diagrams.sync import run_sync
from cogblocks.evaluation.sync_heldout import evaluate_group, heldout_table, summarise
from cogblocks.sync import GatedMotion, MeanPhaseMotion

GROUP = SyncGroup("ring of 5", 5, 0.8, (2.0, 2.5, 3.0, 3.5, 4.0), 1, 3.0)
NOISY = dataclasses.replace(GROUP, noise=GroupNoise(sigma=(0.3,) * 5, drift_spread=(0.1,) * 5, drift_tau=8.0, seed=1))


@pytest.mark.parametrize(("group", "world"), [(GROUP, "model"), (NOISY, "noisy")])
def test_run_sync_reports_the_world_a_gated_motion_found(group, world):
    gated = GatedMotion(MeanPhaseMotion(group.n, group.assisted), adjacency=group.graph)
    rows = run_sync(group, [gated, "mean"])["results"]
    assert rows[0]["world"] == world and "world" not in rows[1]


def test_the_summary_counts_the_groups_found_noisy():
    rows = [
        {"results": [{"policy": "g", "change_pct": c, "bound_fraction": None, "world": w, **_natural()}]}
        for c, w in ((1.0, "noisy"), (-1.0, "model"), (2.0, "noisy"), (0.5, "undecided"))
    ]
    (summary,) = summarise(rows, ["g"])
    assert summary["noisy_share"] == 0.5 and summary["lowered_share"] == 0.25
    without = [{"results": [{k: v for k, v in row["results"][0].items() if k != "world"}]} for row in rows]
    assert "noisy_share" not in summarise(without, ["g"])[0]


def _natural() -> dict:
    return {
        "mean_dev_rad": 0.1,
        "max_dev_rad": 0.2,
        "max_step_rad": 0.01,
        "jumps_per_min": 0.0,
        "peak_speed_ratio": 1.1,
    }


def test_progress_sees_every_group_once_and_the_table_keeps_their_order():
    groups = [dataclasses.replace(g, duration=1.0) for g in random_groups(3, "test", 0)]
    seen = {1: [], 2: []}
    tables = {
        workers: heldout_table(
            3,
            groups=groups,
            policies=["mean"],
            bound=False,
            details=True,
            workers=workers,
            progress=lambda i, row, w=workers: seen[w].append((i, row)),
        )
        for workers in (1, 2)
    }
    assert tables[1] == tables[2]
    for workers, calls in seen.items():
        assert sorted(i for i, _ in calls) == [0, 1, 2], workers
        for index, row in calls:  # each group's own row, whatever order the workers finished in
            assert row == evaluate_group(groups[index], ["mean"], bound=False)
    assert [row["name"] for row in tables[2]["groups"]] == [g.name for g in groups]


def test_the_batched_table_is_the_group_by_group_table():
    shared = [
        dataclasses.replace(TABLE2[2], name="a", duration=2.0),
        dataclasses.replace(TABLE2[3], name="b", duration=1.5),
    ]
    groups = shared + random_groups(2, "validation", 0)
    policies = ["mean", "dqn_raw", "pace"]  # pace does not batch: it runs group by group beside the batch
    kwargs = {"policies": policies, "groups": groups, "bound": False, "details": True, "max_duration": 2.0}
    batched, alone = heldout_table(0, batch=True, **kwargs), heldout_table(0, **kwargs)
    for mine, theirs in zip(batched["groups"], alone["groups"], strict=True):
        assert mine["r_without"] == pytest.approx(theirs["r_without"], abs=1e-12)
        assert [r["policy"] for r in mine["results"]] == policies
        for a, b in zip(mine["results"], theirs["results"], strict=True):
            assert a["r_with"] == pytest.approx(b["r_with"], abs=1e-12)
            assert a["max_dev_rad"] == pytest.approx(b["max_dev_rad"], abs=1e-12)
    for a, b in zip(batched["policies"], alone["policies"], strict=True):
        assert a["mean_change_pct"] == pytest.approx(b["mean_change_pct"], abs=1e-9)
