"""The circular Buffer of the PoP of Amplification."""

import numpy as np
import pytest

from cogblocks.amplification import Buffer
from cogblocks.amplification.buffer import ordered_window
from cogblocks.blocks import Playback
from cogblocks.sim import Diagram, Simulator


def buffered(v, p, capacity):
    d = Diagram()
    pv = d.add("v", Playback(v, unit="mm/s"))
    pp = d.add("p", Playback(p, unit="mm"))
    buf = d.add("buffer", Buffer(capacity))
    d.connect(pv.y, buf.v)
    d.connect(pp.y, buf.p)
    probes = {name: f"buffer.{name}" for name in ("velocity", "position", "count", "length")}
    return d, Simulator(d, probes=probes)


def test_wraps_around_and_keeps_the_newest_samples():
    n, capacity = 13, 5
    v = np.arange(3 * n, dtype=float).reshape(n, 3)
    trace = buffered(v, -v, capacity)[1].run(n_steps=n)
    np.testing.assert_array_equal(trace["count"], np.arange(1, n + 1))
    np.testing.assert_array_equal(trace["length"], np.minimum(np.arange(1, n + 1), capacity))
    for k in range(n):
        ring = trace["velocity"][k]
        assert np.array_equal(ring[k % capacity], v[k])  # the newest sample's row
        window = ordered_window(ring, k + 1)
        np.testing.assert_array_equal(window, v[max(0, k + 1 - capacity) : k + 1])
        np.testing.assert_array_equal(ordered_window(trace["position"][k], k + 1), -window)


def test_non_finite_samples_repeat_the_last_finite_one():
    v = np.array([[1.0, 2, 3], [np.nan, 0, 0], [4, 5, 6]])
    p = np.array([[np.nan, 0, 0], [7.0, 8, 9], [1, 1, 1]])
    trace = buffered(v, p, 4)[1].run(n_steps=3)
    ring_v, ring_p = trace["velocity"][-1], trace["position"][-1]
    np.testing.assert_array_equal(ring_v[:3], [[1, 2, 3], [1, 2, 3], [4, 5, 6]])
    np.testing.assert_array_equal(ring_p[:3], [[0, 0, 0], [7, 8, 9], [1, 1, 1]])
    assert trace["count"][-1] == 3


def test_snapshot_restores_the_ring():
    v = np.random.default_rng(0).normal(size=(30, 3))
    _, sim = buffered(v, v, 8)
    sim.run(n_steps=11)
    snapshot = sim.state_dict()
    first = sim.run(n_steps=7)
    sim.load_state_dict(snapshot)
    again = sim.run(n_steps=7)
    np.testing.assert_array_equal(first["velocity"], again["velocity"])
    sim.reset()
    assert sim.run(n_steps=1)["count"][0] == 1


def test_capacity_is_validated():
    with pytest.raises(ValueError, match="capacity must be an integer >= 1"):
        Buffer(0)


def test_a_batch_buffers_each_run_and_a_bad_sample_stays_in_its_run():
    n, capacity, runs = 9, 4, 3
    rng = np.random.default_rng(5)
    v, p = rng.normal(size=(n, runs, 3)), rng.normal(size=(n, runs, 3))
    v[4, 1, 2] = np.nan  # run 1 keeps its last good sample there
    p[6, 2, 0] = 1e9  # implausible: run 2 keeps its last good position
    d = Diagram()
    pv = d.add("v", Playback(v, unit="mm/s", per_run=True))
    pp = d.add("p", Playback(p, unit="mm", per_run=True))
    buf = d.add("buffer", Buffer(capacity))
    d.connect(pv.y, buf.v)
    d.connect(pp.y, buf.p)
    probes = {name: f"buffer.{name}" for name in ("velocity", "position", "count")}
    sim = Simulator(d, probes=probes, batch=runs)
    assert sim.compiled.per_row == ()
    batched = sim.run(n_steps=n)
    for b in range(runs):
        alone = buffered(v[:, b], p[:, b], capacity)[1].run(n_steps=n)
        for name in probes:
            np.testing.assert_array_equal(batched.run(b)[name], alone[name])
    assert np.isfinite(batched["velocity"]).all()
