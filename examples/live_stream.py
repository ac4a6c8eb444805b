"""A live 100 Hz loop on a motion-capture stream: one sample in, the avatar's position and phase out.

The L1 avatar (Kalman estimate, 100 ms of delay predicted away) and a 1D phase estimator with a
Kalman front end share one tracked marker. The stream is synthetic here: a seeded arm oscillation
that arrives 100 ms late, with tracking drop-outs (frozen values), lost frames (NaN) and spikes.
With a real tracker, replace ``next_sample`` by its read call; the loop stays the same.

    python examples/live_stream.py [seconds]
"""

import sys
import time

import numpy as np

from cogblocks.data.oscillation import generate_oscillation
from cogblocks.phase import PhaseEstimator
from cogblocks.sensing import L1, KalmanEstimator
from cogblocks.sim import Diagram

DT = 0.01  # 100 Hz
DELAY_TICKS = 10  # the stream is 100 ms late
seconds = float(sys.argv[1]) if len(sys.argv) > 1 else 5.0

d = Diagram()
avatar = d.add("l1", L1(DELAY_TICKS * DT, estimator=KalmanEstimator("ca", dims=1)))
phase = d.add("phase", PhaseEstimator(front_end="kalman"))
d.expose_input("p", avatar.p, phase.p)
d.expose_output("p_avatar", avatar.p_avatar)
d.expose_output("theta", phase.theta)
live = d.compile(DT)

# 10 s of warm-up (the phase estimator needs a few periods), then the paced part
n_warm, n_live = 1000, round(seconds / DT)
motion = generate_oscillation((n_warm + n_live + DELAY_TICKS) * DT, seed=7, nan_rate=0.02)
rng = np.random.default_rng(7)
spikes = rng.random(len(motion.position)) < 0.005
stream = np.where(spikes, motion.position + rng.choice([-400.0, 400.0], len(spikes)), motion.position)


def next_sample(k: int) -> float:
    """The sample that arrives at tick ``k``: the marker as it was DELAY_TICKS ago, glitches and all."""
    return float(stream[k - DELAY_TICKS]) if k >= DELAY_TICKS else float("nan")


for k in range(n_warm):  # as fast as possible
    live.step(p=next_sample(k))

compute, late, errors, phase_errors = [], 0, [], []
deadline = time.perf_counter()
for k in range(n_warm, n_warm + n_live):
    start = time.perf_counter()
    out = live.step(p=next_sample(k))
    compute.append(time.perf_counter() - start)
    errors.append(float(out["p_avatar"]) - motion.clean[k])  # against where the hand is now
    phase_errors.append(np.angle(np.exp(1j * (float(out["theta"]) - motion.phase[k - DELAY_TICKS]))))
    # hand the avatar's position to the display here; then wait for the next tick
    deadline += DT
    slack = deadline - time.perf_counter()
    if slack > 0:
        time.sleep(slack)
    else:
        late += 1

raw = stream[n_warm - DELAY_TICKS : n_warm + n_live - DELAY_TICKS] - motion.clean[n_warm : n_warm + n_live]
ms = 1e3 * np.array(compute)
print(
    f"{n_live} ticks at 100 Hz: compute p50 {np.median(ms):.2f} ms, p99 {np.percentile(ms, 99):.2f} ms, "
    f"{late} tick(s) past the deadline"
)
print(
    f"avatar RMS error to the current position: {np.sqrt(np.mean(np.square(errors))):.1f} mm "
    f"(the raw delayed stream: {np.sqrt(np.nanmean(np.square(raw))):.1f} mm, ignoring its NaN)"
)
print(f"phase error to the true phase of the delayed sample: mean {np.mean(np.abs(phase_errors)):.3f} rad")
