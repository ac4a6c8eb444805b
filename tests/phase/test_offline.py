"""mean_cycle, the landmark convention of offline_phase_pca_hilbert, and its circular mean on scipy.stats."""

from __future__ import annotations

import numpy as np

from cogblocks.blocks.angles import TWO_PI, wrap_2pi, wrap_pi
from cogblocks.data.motion3d import generate_motion3d, reference_curve
from cogblocks.phase import mean_cycle, offline_phase_pca_hilbert
from cogblocks.phase.offline import _first_cycle


def test_the_anchor_is_the_hand_written_circular_mean_over_the_first_cycle_to_1e12():
    motion = generate_motion3d(3, duration=20.0)
    raw = np.unwrap(offline_phase_pca_hilbert(motion.position, anchor=False))
    cycle = _first_cycle(raw, "test")
    k = np.arange(round(cycle))
    offset = np.angle(np.exp(1j * (TWO_PI * k / cycle - raw[k])).mean())  # the formula scipy.stats replaces
    anchored = offline_phase_pca_hilbert(motion.position)
    assert np.max(np.abs(wrap_pi(anchored - wrap_2pi(raw + offset)))) < 1e-12


def test_without_the_anchor_phase_zero_is_the_maximum_of_the_projection():
    phase = np.linspace(0.0, 8 * TWO_PI, 1600, endpoint=False) + 1.3  # starts away from the landmark
    positions = reference_curve(phase)
    landmark = offline_phase_pca_hilbert(positions, anchor=False)
    start = offline_phase_pca_hilbert(positions)
    # the two conventions differ by one constant, and the anchored one starts at 0
    shift = wrap_pi(landmark - start)
    assert np.ptp(shift[200:-200]) < 0.05 and abs(wrap_pi(start[0])) < 0.1


def test_the_mean_cycle_of_a_repeated_stroke_is_the_stroke():
    phase = np.linspace(0.0, 10 * TWO_PI, 2000, endpoint=False)
    noisy = reference_curve(phase) + np.random.default_rng(0).normal(0, 1.0, (2000, 3))
    cycle = mean_cycle(noisy, 100)
    assert cycle.shape == (100, 3)
    # phase 0 at the start of the motion: the cycle is the stroke from its own phase 0
    truth = reference_curve(TWO_PI * (np.arange(100) + 0.5) / 100)
    assert np.median(np.linalg.norm(cycle - truth, axis=1)) < 6.0  # mm, on a 320 mm stroke
