"""The altered velocity's step limiter against a hand-written loop, and in the ready diagram."""

import numpy as np
import pytest

from cogblocks.amplification.smoothing import VelocityStepLimiter
from cogblocks.blocks import Playback
from cogblocks.diagrams.amplification import amplification_setup, pop_amplification
from cogblocks.sim import Diagram, Simulator


def _limited(v: np.ndarray, v_h: np.ndarray, **options) -> np.ndarray:
    d = Diagram()
    raw = d.add("raw", Playback(v, unit="mm/s"))
    human = d.add("human", Playback(v_h, unit="mm/s"))
    limiter = d.add("limiter", VelocityStepLimiter(**options))
    d.connect(raw.y, limiter.v)
    d.connect(human.y, limiter.v_h)
    return Simulator(d, probes={"v_a": "limiter.v_a"}).run(n_steps=len(v))["v_a"]


def _reference(v, v_h, factor, floor):
    out, largest = [v[0]], 0.0
    for k in range(1, len(v)):
        largest = max(largest, np.linalg.norm(v_h[k] - v_h[k - 1]))
        step = v[k] - out[-1]
        limit = max(floor, factor * largest)
        size = np.linalg.norm(step)
        out.append(out[-1] + (step * limit / size if size > limit else step))
    return np.array(out)


def test_a_switch_is_spread_over_ticks_no_larger_than_the_humans_steps():
    t = 0.01 * np.arange(120)[:, None]
    v_h = np.hstack([300 * np.sin(2 * t), 100 * t, 0 * t])
    v = v_h.copy()
    v[40:, 0] += 80.0  # a blending switch: 80 mm/s in one tick
    v[90:, 2] -= 30.0
    out = _limited(v, v_h, factor=0.8, floor=0.5)
    np.testing.assert_allclose(out, _reference(v, v_h, 0.8, 0.5), atol=1e-9)
    human_step = np.linalg.norm(np.diff(v_h, axis=0), axis=1).max()
    assert np.linalg.norm(np.diff(out, axis=0), axis=1).max() <= 0.8 * human_step + 1e-9
    np.testing.assert_allclose(out[-5:], v[-5:], atol=1e-9)  # caught up once the switch is spread


def test_a_velocity_without_switches_passes_unchanged():
    t = 0.01 * np.arange(60)[:, None]
    v_h = np.hstack([200 * np.sin(3 * t), 50 * np.cos(t), t])
    np.testing.assert_array_equal(_limited(1.1 * v_h, v_h, factor=2.0, floor=0.0), 1.1 * v_h)


def test_parameters_are_checked_by_name():
    with pytest.raises(ValueError, match="factor"):
        VelocityStepLimiter(factor=0.0)
    with pytest.raises(ValueError, match="floor"):
        VelocityStepLimiter(floor=-1.0)


def test_the_ready_diagram_limits_the_altered_movement():
    setup = amplification_setup()
    human = int(setup.humans[2])  # one whose table blend steps beyond the human's largest step
    movement = (setup.library.velocity[human], setup.library.position[human])
    steps = {}
    for limit in (None, 1.0):
        d = pop_amplification(movement, setup.movements, table=setup.table, encoder=setup.encoder, step_limit=limit)
        trace = Simulator(d).run(n_steps=setup.library.max_len)
        steps[limit] = np.linalg.norm(np.diff(trace["v_a"], axis=0), axis=1).max()
        human_step = np.linalg.norm(np.diff(trace["v_h"], axis=0), axis=1).max()
    assert isinstance(d["l2"]["limiter"], VelocityStepLimiter)
    assert steps[1.0] <= human_step * (1 + 1e-9) < steps[None]
