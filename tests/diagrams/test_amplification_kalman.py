"""The amplification diagram fed by a Kalman estimator of tracked positions."""

import numpy as np
import pytest

from cogblocks.diagrams.amplification import amplification_setup, pop_amplification, run_amplification
from cogblocks.sim import Simulator


def test_kalman_front_end_estimates_the_human_velocity_from_positions():
    setup = amplification_setup(None, 1)
    index = int(setup.humans[0])
    velocity, position = setup.library.velocity[index], setup.library.position[index]
    d = pop_amplification(
        (velocity, position),
        setup.movements,
        table=setup.table,
        encoder=setup.encoder,
        front_end="kalman",
        noise_mm=1.0,
        seed=3,
    )
    trace = Simulator(d).run(n_steps=setup.library.max_len)
    length = int(setup.library.length[index])
    # after a short warm-up the estimated velocity follows the recorded one within a fraction of its peak
    error = np.linalg.norm(trace["v_h"][10:length] - velocity[10:length], axis=1)
    peak = np.linalg.norm(velocity, axis=1).max()
    assert np.sqrt(np.mean(error**2)) < 0.15 * peak
    assert np.linalg.norm(trace["p_h"][length - 1] - position[length - 1]) < 5.0  # mm, at the end of the reach
    assert np.all(np.isfinite(trace["v_a"]))


def test_kalman_front_end_options_are_checked_and_run_end_to_end():
    setup = amplification_setup(None, 1)
    movement = (setup.library.velocity[0], setup.library.position[0])
    with pytest.raises(ValueError, match="pop_amplification: front_end must be one of"):
        pop_amplification(movement, setup.movements, table=setup.table, encoder=setup.encoder, front_end="spline")
    with pytest.raises(ValueError, match="pop_amplification: noise_mm must be a finite number"):
        pop_amplification(movement, setup.movements, table=setup.table, encoder=setup.encoder, noise_mm=-1.0)
    result = run_amplification(("blend",), limit=3, front_end="kalman", noise_mm=1.0)
    assert result["blend"]["n"] == 3 and 0.0 <= result["blend"]["encoded"] <= 1.0
