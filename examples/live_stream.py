"""A live 100 Hz loop on a motion-capture stream over Lab Streaming Layer: the avatar's position and phase out.

The L1 avatar (Kalman estimate, the stream's 100 ms of delay and the inlet's 20 ms predicted away)
and a 1D phase estimator with a Kalman front end read one tracked marker through an ``LSLInlet``,
and two ``LSLOutlet`` blocks publish the avatar's position and phase for a renderer (Unity, Unreal: see docs/live.md).
``run_realtime`` paces the ticks. Without ``--in``, the marker comes from ``stream_markers.py``,
started here, and LSL stays on this machine.

    python examples/live_stream.py [seconds] [--in STREAM]
"""

import argparse
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("seconds", nargs="?", type=float, default=5.0, help="how long to run (default 5 s)")
parser.add_argument("--in", dest="stream", help="a marker stream to read (1 channel, mm); default: simulated")
args = parser.parse_args()

streamer = None
if args.stream is None:
    if "LSLAPICFG" not in os.environ:  # before pylsl loads; the streamer inherits it
        from cogblocks.live.config import use_machine_only_config

        use_machine_only_config("cogblocks-examples")
    args.stream = f"cogblocks-marker-{os.getpid()}"
    script = Path(__file__).with_name("stream_markers.py")
    streamer = subprocess.Popen([sys.executable, str(script), str(args.seconds + 60), "--name", args.stream])

from cogblocks.live import LSLInlet, LSLOutlet, run_realtime  # noqa: E402
from cogblocks.phase import PhaseEstimator  # noqa: E402
from cogblocks.sensing import L1, KalmanEstimator  # noqa: E402
from cogblocks.sim import Diagram  # noqa: E402

DT = 0.01  # 100 Hz
DELAY = 0.1  # how late the marker arrives
BACK = DELAY + 0.02  # how far back the inlet reads it: where two received samples surround the time read

d = Diagram()
# the marker resampled on the tick grid, BACK seconds back; L1 predicts that far ahead
marker = d.add("marker", LSLInlet(args.stream, unit="mm", mode="interpolate", lag=BACK, timeout=10.0))
avatar = d.add("l1", L1(BACK, estimator=KalmanEstimator("ca", dims=1)))
phase = d.add("phase", PhaseEstimator(front_end="kalman"))
d.add("position_out", LSLOutlet("cogblocks-avatar-position", stream_type="MoCap"))
d.add("phase_out", LSLOutlet("cogblocks-avatar-phase", stream_type="Phase"))
d.connect(marker.y, avatar.p, phase.p)
d.connect(avatar.p_avatar, "position_out.u")
d.connect(phase.theta, "phase_out.u")
d.expose_output("sample", marker.y)
d.expose_output("p_avatar", avatar.p_avatar)
d.expose_output("theta", phase.theta)
live = d.compile(DT)

try:
    report = run_realtime(live, args.seconds, 1 / DT, record=True)
finally:
    for block in (marker, live.blocks["position_out"], live.blocks["phase_out"]):
        block.close()  # before the streamer goes, so that the inlet does not try to reconnect
    if streamer is not None:
        streamer.terminate()
        streamer.wait()

s = report.summary()
print(
    f"{s['ticks']} ticks at 100 Hz: compute p50 {s['tick_ms_p50']:.2f} ms, p99 {s['tick_ms_p99']:.2f} ms, "
    f"{s['late_ticks']} tick(s) past their slot; {s['samples_in']} samples in, {s['samples_out']} out, "
    f"oldest sample used {s['max_age_ms']:.0f} ms"
)
# the avatar should lead what the inlet reads by BACK: find the lag that best lines them up
sample, shown = report.trace["sample"], report.trace["p_avatar"]
good = np.isfinite(sample) & np.isfinite(shown)
half = len(sample) // 2
errors = [
    np.nanmean(np.abs(shown[half - lag : -lag] - sample[half:])[good[half:] & good[half - lag : -lag]])
    for lag in range(1, 30)
]
print(
    f"the avatar leads the stream it reads by {10 * (1 + int(np.argmin(errors)))} ms (the inlet reads "
    f"{1e3 * BACK:.0f} ms back); {np.count_nonzero(~np.isfinite(sample))} ticks had no usable sample, "
    f"{np.count_nonzero(~np.isfinite(shown))} showed no avatar position"
)
print(f"phase at the end: {report.trace['theta'][-1]:.2f} rad")
