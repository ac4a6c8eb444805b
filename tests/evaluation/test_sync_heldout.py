"""The held-out evaluation on batched diagrams gives the table it gives group by group."""

from __future__ import annotations

from dataclasses import replace

import pytest

from cogblocks.data.groups import TABLE2, random_groups
from cogblocks.evaluation.sync_heldout import heldout_table


def test_the_batched_table_is_the_group_by_group_table():
    shared = [replace(TABLE2[2], name="a", duration=2.0), replace(TABLE2[3], name="b", duration=1.5)]
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
