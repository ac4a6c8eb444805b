"""The motion computers the ready diagrams know by name: each entry of :data:`MOTIONS` builds a fresh block for a
group (the names ``pop_sync``, ``run_sync``, the held-out evaluation and ``--policy`` take)."""

from __future__ import annotations

import warnings
from collections.abc import Callable
from typing import Any

import numpy as np

from cogblocks.data.groups import SyncGroup
from cogblocks.sim import Block
from cogblocks.sync import MeanPhaseMotion, OscillatorMotion

__all__ = ["DEFAULT_MOTION", "DEFAULT_MOTIONS", "MOTIONS", "MotionRegistry"]


def _mean_motion(group: SyncGroup) -> Block:
    return MeanPhaseMotion(group.n, group.assisted)


def _l3_motion(group: SyncGroup, policy: Any) -> Block:
    return OscillatorMotion(
        policy,
        n=group.n,
        assisted=group.assisted,
        gain=group.gain,
        omega_init=float(np.mean(group.omega)),
        adjacency=group.graph,
    )


def _dqn_raw_motion(group: SyncGroup) -> Block:
    from cogblocks.sync import DQNPolicy

    return _l3_motion(group, DQNPolicy.default())


def _dqn_motion(group: SyncGroup) -> Block:
    from cogblocks.sync import ShieldedMotion

    return ShieldedMotion(_dqn_raw_motion(group), adjacency=group.graph)


def _lookahead_motion(group: SyncGroup) -> Block:
    from cogblocks.sync import LookaheadPolicy

    return _l3_motion(group, LookaheadPolicy.for_group(group))


def _mpc_motion(group: SyncGroup) -> Block:
    from cogblocks.sync import MPCMotion

    return MPCMotion(group.n, group.assisted, adjacency=group.adjacency())


def _pace_motion(group: SyncGroup) -> Block:
    from cogblocks.sync.pacing import PacingMotion

    return PacingMotion(group.n, group.assisted, adjacency=group.graph)


def _plan_motion(group: SyncGroup) -> Block:
    from cogblocks.sync.planned import whole_trial_plan

    return whole_trial_plan(group.n, group.assisted, adjacency=group.graph, end=group.duration)


def _replan_motion(group: SyncGroup) -> Block:
    from cogblocks.sync import RecedingPlanMotion

    # a simulated trial has an end, and every plan reaches it (live_motion plans 30 s ahead, with no end)
    return RecedingPlanMotion(
        group.n, group.assisted, adjacency=group.graph, end=group.duration, horizon=None, compare=None
    )


def _gated_motion(group: SyncGroup) -> Block:
    from cogblocks.sync import GatedMotion

    # replan while the group's own prediction errors say it is the deterministic model, else the circular mean
    return GatedMotion(_replan_motion(group))


def _guard_motion(group: SyncGroup) -> Block:
    from cogblocks.sync.guarded import GuardedPacingMotion

    # the trial's length is part of the task (mean r over [0, T]), not a model of the group: predictions run to it
    return GuardedPacingMotion.for_trial(group.n, group.assisted, adjacency=group.graph, end=group.duration)


class MotionRegistry(dict):
    """Motion computer factories by name: the recommended ones, and retired names that still work for one release.

    Iterating (``list``, ``sorted``) gives the recommended names only; ``name in`` and ``[name]`` also know a
    retired name, whose factory still builds its block, with a :class:`DeprecationWarning` naming the replacement.
    """

    def __init__(self, recommended: dict[str, Callable[[SyncGroup], Block]], retired: dict[str, tuple]) -> None:
        super().__init__(recommended)
        #: retired name -> (factory, what to use instead)
        self.retired: dict[str, tuple[Callable[[SyncGroup], Block], str]] = dict(retired)

    def __contains__(self, name: object) -> bool:
        return dict.__contains__(self, name) or name in self.retired

    def __missing__(self, name: str) -> Callable[[SyncGroup], Block]:
        if name not in self.retired:
            raise KeyError(name)
        factory, instead = self.retired[name]
        warnings.warn(f"motion computer {name!r} is retired: {instead}", DeprecationWarning, stacklevel=2)
        return factory


#: Motion computers available by name: each builds a fresh block for a group. ``replan`` is the planner:
#: it identifies the group online and re-plans to the trial's end every second with the bound's search; ``plan`` is
#: the same planner with one decision, the whole trial planned at once (offline: seconds of CPU in one tick);
#: ``dqn_raw`` is the trained L3 policy (``python -m cogblocks.training.sync_dqn --randomised --seed 0``), ``dqn`` the
#: same behind a shield (followed only while a prediction on the group identified online says it does not lower r);
#: ``lookahead`` plans 25 ticks ahead on the true model; ``mean`` follows the others' circular mean; ``mpc`` plans the
#: reference's frequency 3 s ahead on the identified model; ``gated`` (the default) is ``replan`` behind a
#: :class:`~cogblocks.sync.GatedMotion`, which switches to the circular mean once the group's one-tick prediction
#: errors say it is noisy (people, estimated phases) and reports the world it found. Add an entry to make a policy
#: available to :func:`pop_sync`, :func:`run_sync`, the held-out evaluation and the command line. Retired: ``guard``
#: and ``pace`` (:attr:`MotionRegistry.retired`), which the planner beats on the held-out groups.
MOTIONS = MotionRegistry(
    {
        "dqn": _dqn_motion,
        "dqn_raw": _dqn_raw_motion,
        "gated": _gated_motion,
        "lookahead": _lookahead_motion,
        "mean": _mean_motion,
        "mpc": _mpc_motion,
        "plan": _plan_motion,
        "replan": _replan_motion,
    },
    {
        "guard": (
            _guard_motion,
            "use 'replan' (RecedingPlanMotion), which reaches 0.97 of the whole-run bound's gain on held-out groups "
            "where guard reaches 0.84 (docs/results.md)",
        ),
        "pace": (
            _pace_motion,
            "use 'replan' (RecedingPlanMotion): on the held-out groups of test seed 0 pace lowered r on 1 % (worst "
            "-3.02 %) for 1.06x the gain of 'mean', replan on none for 1.22x (docs/validation/sync.md)",
        ),
    },
)

#: The motion computer :func:`pop_sync` uses when none is given: the planner where the group is the deterministic
#: model (tick for tick), the circular mean where it is noisy (docs/explanation/noisy-groups.md says why).
DEFAULT_MOTION = "gated"

#: What ``run_sync`` and ``cogblocks run sync --group N`` run without a policy list: the Table 3
#: comparison as first published here (``mpc`` is slower and runs when asked for by name).
DEFAULT_MOTIONS = ("dqn", "lookahead", "mean")
