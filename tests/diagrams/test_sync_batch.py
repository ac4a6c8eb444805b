"""The PoP of Social Connectedness on a batch: each run of ``pop_sync`` compiled with ``batch=B`` is a separate run."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from cogblocks.data.groups import TABLE2, GroupNoise
from cogblocks.diagrams.sync import pop_sync
from cogblocks.sim import Simulator
from cogblocks.sync import KuramotoGroup

PROBES = {"theta": "group.theta", "theta_l2": "l2.theta_l2", "lam": "l2.lam", "theta_ref": "l2.theta_ref"}
N_STEPS = 1000


def _alone(group, blender, n_steps=N_STEPS):
    return Simulator(pop_sync(group, motion="mean", blender=blender), probes=PROBES).run(n_steps=n_steps)


@pytest.mark.parametrize("blender", ["deliverable", "continuous"])
def test_every_block_of_the_closed_loop_batches_and_each_run_is_a_separate_run(blender):
    alone = _alone(3, blender)
    sim = Simulator(pop_sync(3, motion="mean", blender=blender), probes=PROBES, batch=3)
    assert sim.compiled.per_row == ()
    trace = sim.run(n_steps=N_STEPS)
    for b in range(3):
        run = trace.run(b)
        for name in PROBES:  # the same operations on arrays: the same bits
            assert np.array_equal(run[name], alone[name]), name
        assert np.max(np.abs(run["r"] - alone["r"])) <= 1e-12  # NumPy's hypot beside one run's math.hypot


def test_the_dqn_motion_computer_batches_its_network_and_each_run_is_a_separate_run():
    alone = Simulator(pop_sync(3, motion="dqn_raw"), probes=PROBES).run(n_steps=N_STEPS)
    sim = Simulator(pop_sync(3, motion="dqn_raw"), probes=PROBES, batch=3)
    assert sim.compiled.per_row == ()
    trace = sim.run(n_steps=N_STEPS)
    for b in range(3):
        for name in PROBES:
            assert np.max(np.abs(trace.run(b)[name] - alone[name])) <= 1e-12, name


def test_a_batch_of_one_is_the_unbatched_run_bit_for_bit():
    alone = _alone(2, "continuous", 500)
    run = Simulator(pop_sync(2, motion="mean"), probes=PROBES, batch=1).run(n_steps=500).run(0)
    for name in [*PROBES, "r"]:
        assert np.array_equal(run[name], alone[name]), name


def test_groups_of_one_size_run_side_by_side_with_their_own_frequencies_and_seeds():
    n = TABLE2[3].n
    noise = GroupNoise(sigma=(0.05,) * n, drift_spread=(0.02,) * n, drift_tau=5.0, seed=0)
    base = replace(TABLE2[3], noise=noise)
    groups = [
        replace(base, omega=tuple(np.asarray(base.omega) * f), noise=replace(noise, seed=s))
        for f, s in ((1.0, 3), (1.1, 4), (0.9, 5))
    ]
    omega = np.array([g.omega for g in groups])
    diagram = pop_sync(base, motion="mean")
    options = base.plant_options()
    options["seed"] = [g.noise.seed for g in groups]
    plant = KuramotoGroup(omega, base.gain, adjacency=base.graph, assisted=base.assisted, **options)
    diagram.replace("group", plant)
    trace = Simulator(diagram, probes=PROBES, batch=3).run(n_steps=600)
    for b, group in enumerate(groups):
        alone = Simulator(pop_sync(group, motion="mean"), probes=PROBES).run(n_steps=600)
        for name in PROBES:
            assert np.array_equal(trace.run(b)[name], alone[name]), (b, name)


def test_nan_in_one_run_never_reaches_another():
    sim = Simulator(pop_sync(3, motion="mean"), probes=PROBES, batch=4)
    clean = Simulator(pop_sync(3, motion="mean"), probes=PROBES, batch=4)
    sim.run(n_steps=200)
    clean.run(n_steps=200)
    for s in (sim, clean):
        s.compiled.blocks["group"].phase[2, 1] = np.nan if s is sim else s.compiled.blocks["group"].phase[2, 1]
    bad, good = sim.run(n_steps=300), clean.run(n_steps=300)
    others = [0, 1, 3]
    for name in [*PROBES, "r"]:
        assert np.array_equal(bad[name][:, others], good[name][:, others]), name
    assert np.isnan(bad["theta"][:, 2]).any()  # the bad run shows its NaN, the blender and r stay finite
    assert np.isfinite(bad["theta_l2"]).all() and np.isfinite(bad["r"]).all()


def test_per_run_parameters_need_their_batch():
    omega = np.array([TABLE2[3].omega] * 2)
    plant = KuramotoGroup(omega, TABLE2[3].gain)
    with pytest.raises(Exception, match=r"omega holds 2 runs .*compile with batch=2"):
        plant.batch = 3
        plant.setup()
    with pytest.raises(ValueError, match="per-run seeds; compile with batch=2"):
        g = KuramotoGroup(TABLE2[3].omega, 0.1, noise=0.1, seed=[1, 2])
        g.setup()


def test_groups_of_one_structure_batch_and_give_run_syncs_figures():
    from cogblocks.diagrams.sync import run_sync
    from cogblocks.diagrams.sync_batch import batches, sync_rows

    groups = [
        replace(TABLE2[2], duration=3.0),
        replace(TABLE2[3], duration=2.0),  # a shorter run in the same batch: its figures over its own samples
        replace(TABLE2[1], duration=1.0),
    ]
    assert batches(groups) == [[0, 1], [2]] and batches(groups, "dqn_raw") == [[0], [1], [2]]
    rows = sync_rows(groups, ["mean", "dqn_raw"], blender="continuous")
    for group, row in zip(groups, rows, strict=True):
        alone = run_sync(group, ["mean", "dqn_raw"], blender="continuous")
        assert row["r_without"] == pytest.approx(alone["r_without"], abs=1e-12)
        for mine, theirs in zip(row["results"], alone["results"], strict=True):
            assert mine.keys() == theirs.keys()
            for key, value in theirs.items():
                assert mine[key] == (value if isinstance(value, str) else pytest.approx(value, abs=1e-12)), key
