"""The held-out table hands every group to ``progress`` as it is done, in any order, and keeps the groups' order."""

import dataclasses

from cogblocks.data.groups import random_groups
from cogblocks.evaluation.sync_heldout import evaluate_group, heldout_table


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
