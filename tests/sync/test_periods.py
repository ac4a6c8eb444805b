"""Decision periods in seconds: counted in ticks of the block's step, the old tick forms warn for one release."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from cogblocks.data.groups import TABLE2
from cogblocks.diagrams.sync import pop_sync
from cogblocks.sim import Simulator
from cogblocks.sync import MPCMotion, PacingMotion


def test_a_period_in_seconds_is_the_same_time_at_any_step():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        block = PacingMotion(3, 0, decide_every=0.5)
    assert block.decide_ticks == 50 and block.decision_period == pytest.approx(0.5)
    own = PacingMotion(3, 0, decide_every=0.5, period=0.02)  # the block's own step: 25 of its ticks
    assert own.decide_ticks == 25 and own.decision_period == pytest.approx(0.5)


def test_a_period_that_is_no_whole_number_of_steps_is_refused_when_compiled():
    group = TABLE2[1]
    block = PacingMotion(group.n, group.assisted, decide_every=0.05)
    with pytest.raises(Exception, match=r"decide_every must be a positive multiple of the block's step \(0.02 s\)"):
        Simulator(pop_sync(group, motion=block), dt=0.02).run(n_steps=2)
    with pytest.raises(ValueError, match=r"PacingMotion: decide_every must be a positive multiple .* got 0.015"):
        PacingMotion(3, 0, decide_every=0.015)


def test_an_int_is_read_as_ticks_with_a_warning_that_says_what_to_write():
    with pytest.warns(DeprecationWarning, match=r"PacingMotion: decide_every is in seconds; .* decide_every=0.5\)"):
        old = PacingMotion(3, 0, decide_every=50)
    assert old.decide_ticks == 50 and old.decide_every == pytest.approx(0.5)


def test_mpc_takes_decide_every_and_its_old_tick_keyword_warns():
    assert MPCMotion(3, 0).decide_ticks == 50  # 0.5 s
    with pytest.warns(DeprecationWarning, match=r"MPCMotion: replan_every \(ticks\) is deprecated; .*=0.2\)"):
        old = MPCMotion(3, 0, replan_every=20)
    new = MPCMotion(3, 0, decide_every=0.2)
    assert old.decide_ticks == new.decide_ticks == 20
    with pytest.warns(DeprecationWarning, match="MPCMotion.replan_every is deprecated: use decide_ticks"):
        assert new.replan_every == 20


def test_the_old_and_new_forms_decide_at_the_same_ticks():
    group = TABLE2[1]
    runs, decisions = [], []
    for every in (0.3, 30):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)
            block = PacingMotion(group.n, group.assisted, adjacency=group.graph, decide_every=every, horizon=2.0)
        runs.append(Simulator(pop_sync(group, motion=block), probes={"ref": "l2.theta_ref"}).run(n_steps=400)["ref"])
        decisions.append(len(block.choices))
    np.testing.assert_array_equal(*runs)
    assert decisions[0] == decisions[1] >= 9  # trusted near tick 100, then a decision every 30 ticks


def test_the_look_ahead_policy_plans_every_decide_every_seconds_and_reads_the_old_ticks_with_a_warning():
    from cogblocks.data.groups import TABLE2
    from cogblocks.sync import LookaheadPolicy
    from cogblocks.sync.model import SyncModel

    model = SyncModel.from_group(TABLE2[1])
    assert LookaheadPolicy(model).decide_ticks == 1
    assert LookaheadPolicy(model, decide_every=0.05).decide_ticks == 5
    with pytest.warns(DeprecationWarning, match=r"replan_every \(ticks\) is deprecated; .*decide_every=0.05\)"):
        old = LookaheadPolicy(model, replan_every=5)
    with pytest.warns(DeprecationWarning, match=r"decide_every=0.07\)"):
        assert LookaheadPolicy(model, 25, 7).decide_ticks == 7  # the former positional ticks
    with pytest.warns(DeprecationWarning, match="LookaheadPolicy.replan_every is deprecated: use decide_ticks"):
        assert old.replan_every == 5
    with pytest.raises(ValueError, match=r"decide_every must be a positive multiple of 0.01 s, got 0.015"):
        LookaheadPolicy(model, decide_every=0.015)
