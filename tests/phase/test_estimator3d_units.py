"""PhaseEstimator3D is unit-free (issue 12): the same motion in mm, m or sensor counts gives the same phase."""

import dataclasses

import numpy as np
import pytest

from cogblocks.blocks.angles import wrap_pi
from cogblocks.data.motion3d import generate_motion3d
from cogblocks.diagrams.phase3d import MOTION3D_SETS, run_phase_estimator


@pytest.fixture(scope="module")
def harder():
    child = np.random.SeedSequence(0).spawn(1)[0]
    motion = generate_motion3d(np.random.default_rng(child), duration=8.0, **MOTION3D_SETS["harder"])
    return motion, run_phase_estimator(motion)


@pytest.mark.parametrize("scale", [1e-3, 1e3])
@pytest.mark.parametrize("reference_too", [True, False])
def test_same_phase_in_any_unit(harder, scale, reference_too):
    motion, in_mm = harder
    # the estimator works in mm: a sanity check that the comparison below is about a real estimate
    valid = in_mm["valid"]
    assert valid.mean() > 0.6  # all but the first period (2.3 s of 8)
    assert np.abs(wrap_pi(in_mm["theta"][valid] - motion.phase[valid])).mean() < 0.05
    # the positions in m (1e-3) or counts (1e3); the reference in the same unit, or left in mm (the fit absorbs it)
    scaled = dataclasses.replace(
        motion, position=motion.position * scale, reference=motion.reference * (scale if reference_too else 1.0)
    )
    other = run_phase_estimator(scaled)
    assert np.array_equal(other["valid"], valid)
    assert other["first_period"] == in_mm["first_period"]
    assert np.abs(wrap_pi(other["theta"] - in_mm["theta"])).max() < 1e-9


@pytest.mark.parametrize("scale", [1e-3, 1.0, 1e3])
def test_motion_starts_after_a_rest_in_any_unit(harder, scale):
    """A still tracker (the same sample repeated) then the motion: recording starts at the motion, in any unit.

    With the rest, the run is the run without it delayed by the rest: the start rule is relative to the
    samples' spread (0 at rest), not a speed in mm/s (50 mm/s would never be reached in m).
    """
    motion = dataclasses.replace(harder[0], position=harder[0].position * scale, reference=harder[0].reference * scale)
    rest = 50
    still = dataclasses.replace(
        motion,
        position=np.concatenate([np.repeat(motion.position[:1], rest, axis=0), motion.position]),
        t=np.arange(rest + len(motion.t)) * motion.dt,
    )
    delayed, direct = run_phase_estimator(still), run_phase_estimator(motion)
    assert not delayed["valid"][:rest].any()
    assert np.array_equal(delayed["valid"][rest:], direct["valid"])
    np.testing.assert_allclose(delayed["theta"][rest:], direct["theta"], rtol=0.0, atol=1e-12)
