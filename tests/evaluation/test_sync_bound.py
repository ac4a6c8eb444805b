"""The yardstick of the motion computers: the best r found by whole-run optimal control or a constant reference."""

from __future__ import annotations

import numpy as np
import pytest

from cogblocks.data.groups import TABLE2
from cogblocks.diagrams.sync import pop_sync
from cogblocks.evaluation.sync_bound import constant_frequency_bound, resimulate, upper_bound
from cogblocks.sim import Simulator
from cogblocks.sync.model import DT


def test_resimulation_matches_the_closed_loop_diagram():
    """A constant-frequency reference through resimulate() gives the r of the same reference in pop_sync."""
    group = TABLE2[1]
    theta_ref = 4.0 * DT * np.arange(301)
    trace = Simulator(pop_sync(group, motion="mean", blender="deliverable"), probes=["l2.theta_ref"]).run(n_steps=301)
    assert resimulate(group, theta_ref) != pytest.approx(float(trace["r"].mean()), abs=1e-6)  # a different reference
    mean_ref = trace["l2.theta_ref"]
    assert resimulate(group, mean_ref) == pytest.approx(float(trace["r"].mean()), abs=1e-12)


DURATION = 3.0


@pytest.fixture(scope="module", params=[1, 3])
def bounded(request):
    group = TABLE2[request.param]
    return group, upper_bound(group, duration=DURATION, max_iter=5)


def test_bound_is_below_one_and_above_every_constant_reference(bounded):
    group, bound = bounded
    assert constant_frequency_bound(group, duration=DURATION) <= bound <= 1.0


@pytest.mark.filterwarnings("ignore:motion computer .* is retired:DeprecationWarning")  # retired names on purpose
@pytest.mark.parametrize("motion", ["mean", "lookahead", "mpc", "pace"])
def test_bound_is_above_the_policies(bounded, motion):
    group, bound = bounded
    r = float(
        Simulator(pop_sync(group, motion=motion, blender="deliverable"))
        .run(n_steps=round(DURATION / DT) + 1)["r"]
        .mean()
    )
    assert r <= bound, f"{motion}: {r} above the bound {bound}"
