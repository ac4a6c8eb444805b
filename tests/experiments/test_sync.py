"""The group comparison as a sweep: the batched runs give the rows the sweep gives run by run."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from cogblocks.data.groups import TABLE2
from cogblocks.experiments.sync import sweep_sync

FIGURES = ["r_mean", "change_pct", "mean_dev_rad", "max_dev_rad"]


def test_a_batched_sweep_has_the_rows_of_the_sweep():
    groups = {
        "2": replace(TABLE2[2], duration=1.0),
        "3": replace(TABLE2[3], duration=0.7),  # batched with group 2, over its own samples
        "1": replace(TABLE2[1], duration=0.5),
    }
    policies = ["mean", "dqn_raw", "pace"]  # pace does not batch: the sweep runs it
    alone = sweep_sync(groups, policies, backend="serial", seeds=2)
    batched = sweep_sync(groups, policies, backend="serial", seeds=2, batch=True)
    keys = ["group", "policy", "replicate", "seed"]
    assert batched[keys].equals(alone[keys])
    assert batched["error"].isna().all()
    np.testing.assert_allclose(batched[FIGURES].to_numpy(), alone[FIGURES].to_numpy(), rtol=0, atol=1e-12)
