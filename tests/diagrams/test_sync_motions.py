"""The registry of motion computers by name: recommended names, and retired ones that warn and still build."""

import warnings

import pytest

from cogblocks.data.groups import TABLE2
from cogblocks.diagrams.sync import MOTIONS, pop_sync
from cogblocks.diagrams.sync_motions import MotionRegistry
from cogblocks.sync import RecedingPlanMotion
from cogblocks.sync.guarded import GuardedPacingMotion
from cogblocks.sync.pacing import PacingMotion


def test_the_listed_names_are_the_recommended_ones_and_the_retired_ones_are_still_known():
    assert sorted(MOTIONS) == ["dqn", "dqn_raw", "gated", "lookahead", "mean", "mpc", "plan", "replan"]
    assert "guard" in MOTIONS and "pace" in MOTIONS and "nope" not in MOTIONS
    assert set(MOTIONS.retired) == {"guard", "pace"}


@pytest.mark.parametrize(("name", "kind"), [("guard", GuardedPacingMotion), ("pace", PacingMotion)])
def test_a_retired_name_builds_its_block_with_a_warning_that_names_the_replacement(name, kind):
    with pytest.warns(DeprecationWarning, match=rf"motion computer '{name}' is retired: use 'replan' \(RecedingPlan"):
        motion = pop_sync(1, motion=name)["l2.motion"]
    assert type(motion) is kind


def test_a_recommended_name_builds_without_a_warning_and_an_unknown_one_is_a_key_error():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert isinstance(MOTIONS["replan"](TABLE2[1]), RecedingPlanMotion)
    with pytest.raises(KeyError, match="nope"):
        MOTIONS["nope"]
    with pytest.raises(ValueError, match=r"pop_sync: motion must be one of \['dqn', 'dqn_raw', 'gated', 'lookahead'"):
        pop_sync(1, motion="nope")


def test_a_registry_of_ones_own_keeps_its_retired_names_apart():
    registry = MotionRegistry({"a": lambda group: None}, {"b": (lambda group: "built", "use 'a'")})
    assert list(registry) == ["a"] and "b" in registry
    with pytest.warns(DeprecationWarning, match="motion computer 'b' is retired: use 'a'"):
        assert registry["b"](None) == "built"


def test_the_default_is_the_planner_behind_the_noise_gate_built_as_replan_is():
    from cogblocks.diagrams.sync_motions import DEFAULT_MOTION
    from cogblocks.sync import GatedMotion, MeanPhaseMotion
    from cogblocks.sync.gated import DECIDE_AFTER, THRESHOLD, NoiseGate

    group = TABLE2[2]
    motion = pop_sync(2)["l2.motion"]
    assert DEFAULT_MOTION == "gated" and isinstance(motion, GatedMotion)
    planner, replan = motion["model"], MOTIONS["replan"](group)
    assert type(planner) is RecedingPlanMotion
    assert planner.init_arguments == replan.init_arguments  # built as MOTIONS["replan"] builds it
    assert planner.end == group.duration and planner.horizon_ticks is None
    assert (planner.n, planner.assisted) == (group.n, group.assisted)
    gate = motion["gate"]
    assert isinstance(gate, NoiseGate) and isinstance(motion["fallback"], MeanPhaseMotion)
    assert (gate.fallback, gate.decide_after, gate.threshold) == ("mean", DECIDE_AFTER, THRESHOLD)
    assert motion.world == "undecided"
