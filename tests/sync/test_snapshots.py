"""Snapshots of the PoP closed loop with a motion computer mid-decision: a restored diagram continues bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from cogblocks.data.groups import TABLE2
from cogblocks.diagrams.sync import pop_sync
from cogblocks.sim import Simulator
from cogblocks.sync import MPCMotion

# guard and pace are retired names, snapshotted here as long as they are built
pytestmark = pytest.mark.filterwarnings("ignore:motion computer .* is retired:DeprecationWarning")

PROBES = {"ref": "l2.theta_ref"}


def _load(sim: Simulator, snapshot) -> None:
    """Load a snapshot taken with ``state_dict`` (a dict) or ``save_state`` (a file)."""
    if isinstance(snapshot, dict):
        sim.load_state_dict(snapshot)
    else:
        sim.load_state(snapshot)


def _assert_same_run(first, second) -> None:
    np.testing.assert_array_equal(first["r"], second["r"])
    np.testing.assert_array_equal(first["ref"], second["ref"])


def _in_progress(name: str, ticks: int, motion) -> None:
    """Check that ``motion`` is mid-way through a decision after ``ticks`` ticks, at the stage the test means."""
    if name == "guard":  # trusted at tick 100: a decision spread over ticks 100-399, its lead done by tick 103
        assert motion.job is not None and 0 < motion.job.done_steps < motion.job.total_steps
        assert (motion.job.done_steps < motion.job.lead_steps) == (ticks == 101)
    elif name == "dqn":  # trusted at tick 100: a rollout of 200 policy ticks, four a tick, then its backup part
        assert motion.job is not None and 0 < motion.job.done_steps < motion.job.steps
    else:  # pace decides within one tick: nothing is in progress, but its first decision (tick 100) is taken
        assert motion.model() is not None and motion.choices


@pytest.mark.parametrize("fresh", [False, True], ids=["same-diagram", "new-diagram"])
@pytest.mark.parametrize("via", ["file", "dict"])
@pytest.mark.parametrize(("name", "ticks"), [("guard", 101), ("guard", 123), ("dqn", 123), ("pace", 123)])
def test_a_closed_loop_continues_bit_for_bit_from_a_snapshot(tmp_path, name, ticks, via, fresh):
    """Saved mid-decision (``save_state`` or ``state_dict``), continued 300 ticks; a second simulator, of the same
    diagram or of a new one built alike, loads the snapshot and runs the same 300 ticks, to the bit."""
    diagram = pop_sync(2, motion=name, blender="deliverable")
    sim = Simulator(diagram, probes=PROBES)
    sim.run(n_steps=ticks)
    _in_progress(name, ticks, sim.compiled.blocks["l2.motion"])
    if via == "file":
        snapshot = tmp_path / "snap.npz"
        sim.save_state(snapshot)
    else:
        snapshot = sim.state_dict()
    first = sim.run(n_steps=300)
    other = Simulator(pop_sync(2, motion=name, blender="deliverable") if fresh else diagram, probes=PROBES)
    other.run(n_steps=7)  # a plan with a state of its own, which the snapshot replaces
    _load(other, snapshot)
    _assert_same_run(first, other.run(n_steps=300))
    assert np.ptp(first["ref"]) > 0.0


@pytest.mark.parametrize("name", ["guard", "dqn"])
def test_a_reset_drops_the_decision_in_progress(name):
    sim = Simulator(pop_sync(2, motion=name, blender="deliverable"), probes=PROBES)
    sim.run(n_steps=123)
    sim.reset()
    motion = sim.compiled.blocks["l2.motion"]
    assert motion.job is None and not motion.job_active
    again = sim.run(n_steps=423)
    _assert_same_run(again, Simulator(pop_sync(2, motion=name, blender="deliverable"), probes=PROBES).run(n_steps=423))


def test_mpc_continues_bit_for_bit_from_a_snapshot_taken_mid_solve(tmp_path):
    """The solve's iterate and multipliers are block state. The CPU-time limit of a chunk is lifted here: a chunk it
    stops ends where the machine's speed lets it, which no run reproduces (MPCMotion's notes)."""
    group = TABLE2[2]

    def motion() -> MPCMotion:
        return MPCMotion(group.n, group.assisted, adjacency=group.adjacency(), time_limit_ms=1e4)

    sim = Simulator(pop_sync(group, motion=motion(), blender="deliverable"), probes=PROBES)
    sim.run(n_steps=152)  # the decision of tick 150 is being refined, one chunk of IPOPT a tick
    block = sim.compiled.blocks["l2.motion"]
    assert block.solving and 0 < block.solve_iterations < block.max_iter
    sim.save_state(tmp_path / "snap.npz")
    snapshot = sim.state_dict()
    first = sim.run(n_steps=300)
    for loaded in (tmp_path / "snap.npz", snapshot):
        other = Simulator(pop_sync(group, motion=motion(), blender="deliverable"), probes=PROBES)
        _load(other, loaded)
        _assert_same_run(first, other.run(n_steps=300))
