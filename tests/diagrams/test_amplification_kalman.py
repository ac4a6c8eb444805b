"""The amplification diagram fed by a Kalman estimator of tracked positions."""

import math
import re

import numpy as np
import pytest

from cogblocks.amplification.judges import FEATURES, kinematic_features
from cogblocks.diagrams.amplification import SMOOTHING_HZ, amplification_setup, pop_amplification, run_amplification
from cogblocks.diagrams.tracking import AUTO_HIGHEST_HZ, AUTO_REST_BOUND, REST_QUANTILE
from cogblocks.sensing import rest_speed_bound
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
    trace = Simulator(d, probes={"v_hat": "tracking.v_hat"}).run(n_steps=setup.library.max_len)
    length = int(setup.library.length[index])
    # after a short warm-up the estimated velocity follows the recorded one within a fraction of its peak (the probe
    # "v_h" is the recorded velocity itself: the estimate is the tracker's output)
    error = np.linalg.norm(trace["v_hat"][10:length] - velocity[10:length], axis=1)
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


def _replay(setup, index, **options):
    velocity, position = setup.library.velocity[index], setup.library.position[index]
    d = pop_amplification(
        (velocity, position), setup.movements, table=setup.table, encoder=setup.encoder, e_des=setup.e_des, **options
    )
    smoothed = options.get("front_end") == "kalman" and options.get("smoothing_hz", SMOOTHING_HZ) is not None
    fed = {"fed": "still.y" if smoothed else "tracking.v_hat"} if options.get("front_end") == "kalman" else None
    return Simulator(d, probes=fed).run(n_steps=setup.library.max_len)


@pytest.mark.parametrize("noise", [0.3, 1.0])
def test_the_smoothed_front_end_sees_the_hand_stop(noise):
    setup = amplification_setup(None, 1)
    index = int(setup.humans[1])
    after = int(setup.library.length[index]) + 30  # the hand has been still for 0.3 s
    smoothed = _replay(setup, index, front_end="kalman", noise_mm=noise, seed=5)["fed"][after:]
    raw = _replay(setup, index, front_end="kalman", noise_mm=noise, seed=5, smoothing_hz=None)["fed"][after:]
    # the architecture's rest speed is 1 mm/s: the raw estimate never reaches it, the gated one is exactly zero
    assert np.mean(np.linalg.norm(raw, axis=1) > 1.0) > 0.95
    assert np.mean(np.all(smoothed == 0.0, axis=1)) > 0.95


@pytest.mark.parametrize("noise", [0.3, 1.0])
def test_the_smoothed_front_end_emits_a_movement_as_smooth_as_the_recorded_one(noise):
    setup = amplification_setup(None, 0)
    jerk = {}
    for index in setup.humans[:3]:
        runs = {
            "recorded": {},
            "smoothed": {"front_end": "kalman", "noise_mm": noise, "seed": int(index)},
            "raw": {"front_end": "kalman", "noise_mm": noise, "seed": int(index), "smoothing_hz": None},
        }
        for name, options in runs.items():
            emitted = _replay(setup, int(index), **options)["v_a"]
            jerk.setdefault(name, []).append(
                kinematic_features(emitted, setup.library.dt)[FEATURES.index("log_mean_jerk")]
            )
    recorded, smoothed, raw = (np.array(jerk[name]) for name in ("recorded", "smoothed", "raw"))
    # the tracker's noise makes the emitted movement rougher than the recorded one (log 0.5: a mean jerk 1.6 times)
    assert np.all(raw > recorded + 0.5)
    # smoothed, it is less rough and closer to the recorded one, within that factor
    assert np.all(smoothed < raw)
    assert np.all(np.abs(smoothed - recorded) < np.abs(raw - recorded))
    assert np.all(np.abs(smoothed - recorded) < 0.5)


@pytest.mark.parametrize(("value", "shown"), [(0.0, "0.0"), (50.0, "50.0"), (math.nan, "nan"), ("fast", "'fast'")])
def test_the_smoothing_option_is_checked(value, shown):
    setup = amplification_setup(None, 1)
    movement = (setup.library.velocity[0], setup.library.position[0])
    message = f"pop_amplification: smoothing_hz must be a finite number in (0.0, 50.0), 'auto' or None, got {shown}"
    with pytest.raises(ValueError, match=re.escape(message)):
        pop_amplification(
            movement, setup.movements, table=setup.table, encoder=setup.encoder, front_end="kalman", smoothing_hz=value
        )


def test_auto_smoothing_follows_the_tracker_s_noise():
    setup = amplification_setup(None, 1)
    movement = (setup.library.velocity[0], setup.library.position[0])
    blocks = {}
    for noise in (0.0, 0.3, 1.0, 2.0):
        d = pop_amplification(
            movement, setup.movements, table=setup.table, encoder=setup.encoder, front_end="kalman",
            noise_mm=noise, smoothing_hz="auto",
        )  # fmt: skip
        blocks[noise] = (d["smooth"].cutoff, d["still"].threshold)
    # a quiet tracker keeps the highest cut-off; a noisy one is smoothed until a still hand shows the bound
    assert blocks[0.0] == (AUTO_HIGHEST_HZ, 0.0)
    assert blocks[0.3][0] == AUTO_HIGHEST_HZ and blocks[0.3][1] < AUTO_REST_BOUND
    for noise in (1.0, 2.0):
        cutoff, threshold = blocks[noise]
        assert cutoff < AUTO_HIGHEST_HZ and threshold == pytest.approx(AUTO_REST_BOUND, rel=1e-4)
        assert threshold == rest_speed_bound(noise, cutoff, measurement_noise=noise, quantile=REST_QUANTILE)
    assert blocks[2.0][0] < blocks[1.0][0]
