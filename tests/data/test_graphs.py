"""Groups on any graph: graph specs, the dense and edge-list coupling, and the diagram, model and
environment following the group's graph."""

import dataclasses

import numpy as np
import pytest
import scipy.sparse as sp

from cogblocks.data.graphs import adjacency_matrix, complete_adjacency, graph_edges, random_adjacency, ring_adjacency
from cogblocks.data.groups import TABLE2, SyncGroup
from cogblocks.diagrams.sync import pop_sync
from cogblocks.sim import Diagram, Simulator
from cogblocks.sync import KuramotoGroup, OscillatorMotion, SyncModel
from cogblocks.sync.coupling import Coupling
from cogblocks.sync.motion import HOLD_ACTION
from cogblocks.training.sync_env import evaluate

DT = 0.01


def euler_by_edges(omega, gain, a, n_steps):
    """Independent reference: explicit loops over the nonzero a_ij, phases wrapped to [0, 2π)."""
    theta = np.zeros(len(omega))
    out = np.empty((n_steps, len(omega)))
    edges = [(i, j, a[i, j]) for i in range(len(omega)) for j in range(len(omega)) if a[i, j] != 0]
    for k in range(n_steps):
        out[k] = theta
        pull = np.zeros(len(omega))
        for i, j, w in edges:
            pull[i] += w * np.sin(theta[j] - theta[i])
        theta = np.mod(theta + DT * (omega + gain * pull), 2 * np.pi)
    return out


def run_group(block, n_steps):
    d = Diagram()
    d.add("group", block)
    return Simulator(d, probes=["group.theta"]).run(n_steps=n_steps)["group.theta"]


def angle_gap(x, y):
    return np.abs(np.angle(np.exp(1j * (x - y))))


def weighted_directed(n, density, seed):
    rng = np.random.default_rng(seed)
    a = np.where(rng.random((n, n)) < density, rng.uniform(0.2, 2.0, (n, n)), 0.0)
    np.fill_diagonal(a, 0.0)
    return a


@pytest.mark.parametrize("n", [2, 3, 7, 12])
def test_ring_edges_are_the_ring_matrix(n):
    rows, cols, w = graph_edges("ring", n)
    dense = np.zeros((n, n))
    np.add.at(dense, (rows, cols), w)
    np.testing.assert_array_equal(dense, ring_adjacency(n))
    assert np.all(np.diff(rows * n + cols) > 0)  # sorted, each edge once


def test_graph_specs():
    np.testing.assert_array_equal(adjacency_matrix("all", 4), np.ones((4, 4)) - np.eye(4))
    a = adjacency_matrix(("random", 0.5, 3), 9)
    np.testing.assert_array_equal(a, a.T)
    np.testing.assert_array_equal(a, random_adjacency(9, 0.5, 3))
    assert not np.array_equal(a, random_adjacency(9, 0.5, 4))
    assert set(np.unique(a)) <= {0.0, 1.0} and np.all(np.diag(a) == 0)
    assert np.all(random_adjacency(6, 1.0, 0) == complete_adjacency(6))
    with pytest.raises(ValueError, match="graph must be 'ring', 'all'"):
        adjacency_matrix("star", 4)
    with pytest.raises(ValueError, match="must be 4x4"):
        adjacency_matrix(np.ones((3, 3)), 4)
    with pytest.raises(ValueError, match="p must be in"):
        adjacency_matrix(("random", 1.5, 0), 4)


@pytest.mark.parametrize(
    "graph", ["ring", "all", ("random", 0.3, 1), weighted_directed(9, 0.4, 0), sp.csr_matrix(ring_adjacency(9))]
)
def test_group_follows_its_graph(graph):
    omega = np.linspace(2.0, 4.0, 9)
    got = run_group(KuramotoGroup(omega, 0.7, adjacency=graph), 150)
    ref = euler_by_edges(omega, 0.7, adjacency_matrix(graph, 9), 150)
    assert angle_gap(got, ref).max() < 1e-9


@pytest.mark.parametrize("graph", ["ring", ("random", 0.05, 2), weighted_directed(120, 0.08, 1)])
def test_sparse_coupling_equals_dense(graph):
    n = 120
    omega = np.random.default_rng(5).normal(3.0, 1.0, n)
    sparse = KuramotoGroup(omega, 0.4, adjacency=graph, sparse=True)
    dense = KuramotoGroup(omega, 0.4, adjacency=graph, sparse=False)
    assert sparse.coupling.sparse and not dense.coupling.sparse
    assert angle_gap(run_group(sparse, 300), run_group(dense, 300)).max() < 1e-12
    theta = np.random.default_rng(6).uniform(0, 2 * np.pi, n)
    np.testing.assert_allclose(
        sparse.coupling.pull(theta, np.zeros(n)), dense.coupling.pull(theta, np.zeros(n)), rtol=0, atol=1e-12
    )


def test_the_form_is_chosen_from_size_and_density():
    assert not Coupling("ring", 7).sparse
    assert Coupling("ring", 1000).sparse
    assert not Coupling("all", 200).sparse
    assert isinstance(KuramotoGroup(np.ones(100_000), 1.0).adjacency, sp.csr_matrix)  # never built dense


def test_sync_group_graph_field():
    assert all(g.graph == "ring" for g in TABLE2.values())
    np.testing.assert_array_equal(TABLE2[3].adjacency(), ring_adjacency(7))
    a = weighted_directed(4, 0.7, 2)
    g = SyncGroup("m", 4, 1.0, (1.0, 2.0, 3.0, 4.0), 1, 1.0, graph=a)
    assert isinstance(g.graph, tuple) and g.graph_kind == "matrix"
    np.testing.assert_array_equal(g.adjacency(), a)
    assert hash(g) == hash(SyncGroup("m", 4, 1.0, (1.0, 2.0, 3.0, 4.0), 1, 1.0, graph=a.copy()))
    with pytest.raises(ValueError, match="zero diagonal"):
        SyncGroup("m", 4, 1.0, (1.0, 2.0, 3.0, 4.0), 1, 1.0, graph=np.eye(4))
    with pytest.raises(ValueError, match="graph must be"):
        SyncGroup("m", 4, 1.0, (1.0, 2.0, 3.0, 4.0), 1, 1.0, graph="star")


def hold_policy():
    class Hold:
        def reset(self, omega_init):
            pass

        def act(self, context):
            return HOLD_ACTION

    return Hold()


def test_diagram_and_model_agree_on_a_weighted_directed_graph():
    a = weighted_directed(6, 0.6, 3)
    group = SyncGroup("directed", 6, 0.8, (2.0, 2.5, 3.1, 3.3, 4.0, 2.2), 2, 2.0, graph=a)
    motion = OscillatorMotion(
        hold_policy(), n=6, assisted=2, gain=0.8, omega_init=float(np.mean(group.omega)), adjacency=a
    )
    np.testing.assert_array_equal(motion.coupling, a[2])
    n_steps = round(group.duration / DT) + 1
    r_diagram = Simulator(pop_sync(group, motion=motion, blender="deliverable")).run(n_steps=n_steps)["r"].mean()
    r_model = evaluate(hold_policy(), group)["r_with"]
    assert abs(r_diagram - r_model) < 1e-9
    without = Simulator(pop_sync(group, l2=False), probes=["group.theta"]).run(n_steps=50)["group.theta"]
    assert angle_gap(without, euler_by_edges(np.array(group.omega), 0.8, a, 50)).max() < 1e-9


def test_model_uses_the_sparse_product_for_large_groups():
    group = SyncGroup("big ring", 200, 0.5, tuple(np.linspace(2, 4, 200)), 7, 1.0)
    model = SyncModel.from_group(group)
    assert sp.issparse(model.adjacency)
    dense = dataclasses.replace(model, adjacency=model.adjacency.toarray())
    rng = np.random.default_rng(0)
    theta = rng.uniform(0, 2 * np.pi, (11, 200))
    theta_l3, omega_l3 = rng.uniform(0, 2 * np.pi, 11), rng.normal(3, 1, 11)
    tilde, _, _ = model.blend(theta, theta_l3, np.full(11, 1.0))
    for got, want in zip(
        model.advance(theta, tilde, theta_l3, omega_l3), dense.advance(theta, tilde, theta_l3, omega_l3), strict=True
    ):
        assert angle_gap(got, want).max() < 1e-12
    np.testing.assert_array_equal(model.neighbours, ring_adjacency(200)[7])


@pytest.mark.parametrize("graph", ["ring", "all", ("random", 0.5, 4), "weighted"])
def test_every_identifying_motion_computer_models_the_graph_it_is_given(graph):
    from cogblocks.sync import MPCMotion, PacingMotion, RecedingPlanMotion
    from cogblocks.sync.planned import whole_trial_plan

    spec = weighted_directed(5, 0.6, 1) if graph == "weighted" else graph
    expected = adjacency_matrix(spec, 5)
    expected = expected.toarray() if sp.issparse(expected) else expected
    blocks = [
        MPCMotion(5, 1, adjacency=spec),
        PacingMotion(5, 1, adjacency=spec),
        whole_trial_plan(5, 1, end=5.0, adjacency=spec),
        RecedingPlanMotion(5, 1, end=5.0, adjacency=spec),
    ]
    for block in blocks:
        np.testing.assert_array_equal(block.adjacency, expected)
        np.testing.assert_array_equal(block.identifier().adjacency, expected)
