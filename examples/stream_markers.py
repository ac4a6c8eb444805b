"""A simulated motion-capture marker on Lab Streaming Layer: test outlet for the live examples.

Streams a seeded arm oscillation (1 channel, mm, 100 Hz) as a tracker would: each sample is sent
100 ms after it was captured and stamped with its capture time, with tracking drop-outs (frozen
values), lost frames (NaN) and spikes. Without ``LSLAPICFG`` set, LSL is kept on this machine.

    python examples/stream_markers.py [seconds] [--name NAME]
"""

import argparse
import os
import time

import numpy as np

if "LSLAPICFG" not in os.environ:  # before pylsl loads: stay on this machine unless told otherwise
    from cogblocks.live.config import use_machine_only_config

    use_machine_only_config("cogblocks-examples")

import pylsl  # noqa: E402

from cogblocks.data.oscillation import generate_oscillation  # noqa: E402

DT = 0.01  # 100 Hz
DELAY = 0.1  # seconds between capture and sending

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("seconds", nargs="?", type=float, default=5.0, help="how long to stream (default 5 s)")
parser.add_argument("--name", default="cogblocks-marker", help="stream name (default cogblocks-marker)")
args = parser.parse_args()

motion = generate_oscillation(args.seconds + DELAY, seed=7, nan_rate=0.02)
rng = np.random.default_rng(7)
spikes = rng.random(len(motion.position)) < 0.005
samples = np.where(spikes, motion.position + rng.choice([-400.0, 400.0], len(spikes)), motion.position)

info = pylsl.StreamInfo(args.name, "MoCap", 1, 1 / DT, pylsl.cf_double64, f"{args.name}-simulated")
channel = info.desc().append_child("channels").append_child("channel")
channel.append_child_value("label", "hand_x")
channel.append_child_value("unit", "mm")
outlet = pylsl.StreamOutlet(info)

captured = pylsl.local_clock() - DELAY  # the capture time of sample 0
start = time.perf_counter()
for k, value in enumerate(samples):
    # sample k was captured at `captured + k DT` and leaves DELAY later, i.e. at start + k DT
    wait = start + k * DT - time.perf_counter()
    if wait > 0:
        time.sleep(wait)
    outlet.push_sample([value], captured + k * DT)
print(f"streamed {len(samples)} samples of {args.name!r} ({np.isnan(samples).sum()} lost, {spikes.sum()} spikes)")
