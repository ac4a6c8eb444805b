"""The thirteenth round's option of the optimised blender: the human predicted as the mean of several library
movements (``plain_blender(neighbours=k)``, :mod:`cogblocks.amplification.neighbours`)."""

from types import SimpleNamespace

import numpy as np
import pytest
import torch

from cogblocks.amplification.neighbours import NeighbourPrediction
from cogblocks.data.reach import generate_reach_library
from cogblocks.diagrams.amplification import amplification_setup, replay_movement
from cogblocks.diagrams.amplification_setup import blender_networks
from tests.amplification.optimal_helpers import PredictionRecorder, options, plain_blender

torch.set_num_threads(1)


def prefix_distances(library_velocity: np.ndarray, human: np.ndarray, t: int) -> np.ndarray:
    """Σ_{s < t} ‖v_j(s) − v_h(s)‖ for every movement j, straight from the definition."""
    return np.linalg.norm(np.asarray(library_velocity, dtype=np.float64)[:, :t] - human[None, :t], axis=2).sum(axis=1)


@pytest.mark.parametrize("seed", range(3))
def test_running_sums_are_the_prefix_distances(seed):
    library = generate_reach_library(seed, n_subjects=2, n_fear=4, n_no_fear=4)
    rng = np.random.default_rng(seed)
    human = rng.normal(scale=150.0, size=(library.max_len, 3))
    k = 3
    prediction = NeighbourPrediction("test", library, k)
    block = SimpleNamespace(human=human, neighbour_sums=np.zeros(len(library)))
    for t in range(library.max_len):
        prediction.record(block, t)
        if t in (0, 9, 57, library.max_len - 1):
            expected = prefix_distances(library.velocity, human, t + 1)
            np.testing.assert_allclose(block.neighbour_sums, expected, rtol=1e-12)
            nearest = np.argsort(expected, kind="stable")[:k]
            np.testing.assert_array_equal(prediction.nearest(block.neighbour_sums), nearest)
            np.testing.assert_allclose(prediction.basis(block, -1), library.velocity[nearest].mean(axis=0), rtol=1e-12)


def test_one_neighbour_is_eta_and_keeps_no_state():
    library = generate_reach_library(1, n_subjects=2, n_fear=3, n_no_fear=3)
    prediction = NeighbourPrediction("test", library, 1)
    block = SimpleNamespace(human=np.ones((library.max_len, 3)))
    prediction.record(block, 5)  # nothing to keep: no neighbour_sums needed
    np.testing.assert_array_equal(prediction.basis(block, 4), library.velocity[4])
    setup = amplification_setup(None, 0)
    blender = plain_blender(setup.movements, setup.encoder, solver="linearised")
    assert blender.neighbours == 1 and "neighbour_sums" not in blender.state_names
    blender = plain_blender(setup.movements, setup.encoder, solver="linearised", neighbours=4)
    assert blender.neighbours == 4 and "neighbour_sums" in blender.state_names
    assert blender.state_dict()["state"]["neighbour_sums"].shape == (len(setup.movements),)


def test_bad_neighbours():
    setup = amplification_setup(None, 1)
    n = len(setup.movements)
    with pytest.raises(ValueError, match=f"OptimalBlender: neighbours must be at most the library's {n} movements"):
        plain_blender(setup.movements, setup.encoder, solver="linearised", neighbours=n + 1)
    with pytest.raises(ValueError, match="neighbours"):
        plain_blender(setup.movements, setup.encoder, solver="linearised", neighbours=0)
    with pytest.raises(ValueError, match="neighbours"):
        plain_blender(setup.movements, setup.encoder, solver="linearised", neighbours=2.5)


@pytest.mark.parametrize("e_des", [1, 0])
def test_decisions_plan_on_the_neighbours_mean(e_des):
    setup = amplification_setup(None, e_des)
    blender = PredictionRecorder(
        setup.movements, blender_networks(setup.encoder), setup.table, e_des=e_des, subspace=setup.subspace,
        **options(iterations=3, neighbours=5),
    )  # fmt: skip
    # the rule's emission itself, without the limiter that smooths it
    trace = replay_movement(setup, int(setup.humans[1]), blender, step_limit=None)
    v_h = np.asarray(trace["v_h"], dtype=np.float64)
    velocity = setup.movements.velocity
    moving_decisions = 0
    for decision, predicted in blender.predictions:
        expected = np.zeros_like(velocity[0], dtype=np.float64)
        if np.linalg.norm(v_h[decision - 1]) > blender.rest_speed:  # a human at rest is predicted to stay so
            nearest = np.argsort(prefix_distances(velocity, v_h, decision), kind="stable")[:5]
            expected[decision:] = velocity[nearest].mean(axis=0)[decision:]
            moving_decisions += 1
        np.testing.assert_allclose(predicted, expected, rtol=0, atol=1e-9)
    assert moving_decisions >= 3
    # emitted as planned after the last commit (emit="tail"): the movement its check classified, on that prediction
    committed = [i for i, r in enumerate(blender.results) if r.status in ("converged", "accepted")]
    t0 = blender.results[committed[-1]].tick + blender.solve_ticks - 1
    free = [s for s in range(t0, blender.end) if s not in blender.guarded_ticks]
    assert blender.as_planned == 1 and len(free) >= blender.end - t0 - 2
    np.testing.assert_allclose(trace["v_a"][free], blender.checked[committed[-1]][free], rtol=0, atol=1e-9)
    # the state holds the whole replay's distances at the end
    np.testing.assert_allclose(blender.neighbour_sums, prefix_distances(velocity, v_h, len(v_h)), rtol=1e-9)
