"""The sync diagram run live at 100 Hz on real LSL streams (loopback only): pacing and end-to-end latency.

A peer process streams the phases of Table 2's group 1 at 120 Hz and reads the published θ_L2;
this process runs the live sync diagram (``cogblocks.live.live_sync``: LSLInlet → L2Sync with the
trained DQN policy → LSLOutlet) with ``run_realtime``, once while a third process keeps one core
busy, and once without it. LSL uses the machine-only configuration (``cogblocks.live.config``).

* ``live.sync.late_share``: share of ticks that finished after their slot, under load; reference:
  the same share without the load, floored at one tick (so that a clean reference stays finite).
* ``live.sync.tick_ms_p99``: 99th percentile of the tick's computation (LSL pull, L2, push), under
  load; reference: the 10 ms budget.
* ``live.sync.offline_step_ms_p99``: the same diagram stepped back to back without pacing (same
  inputs, same load); reference: the 10 ms budget. ``tick_ms_p99`` over it is the cost of running live.
* ``live.sync.latency_ms_p50`` / ``_p99``: from the stream time that an output reflects (the inlet
  interpolates the stream 20 ms before the tick's nominal time, where two pushed samples surround
  it) to that output received by the peer's inlet, under load; reference: the 10 ms tick period.
  The 20 ms of the inlet's lag are its floor.
* ``live.phase.interpolate_error_rad``: mean phase error of the live ``phase`` diagram on a 1 Hz
  sine streamed at 100 Hz (30 s, 8 s with --quick, from the fourth second on), against the true
  phase at the stream time each output stands for, with the inlet interpolating on the tick grid,
  under load; reference: the same with the inlet giving the latest sample, whose values jitter
  with the ticks.

    python benchmarks/run.py --only live [--quick]      (two 60 s runs; 10 s with --quick)
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from cogblocks.live.config import use_machine_only_config
from cogblocks.sim import Block

BUDGET_MS = 10.0
DT = 0.01
ROOT = Path(__file__).resolve().parent.parent
# The peer streams at 120 Hz, a common tracker rate: its samples fall at every offset from the ticks,
# so the latency covers every wait for the next tick (at 100 Hz it would be one offset, fixed per run).
PEER_DT = 1 / 120


def _peer(in_name: str, out_name: str, seconds: float) -> None:
    """Stream group 1's phases to ``in_name`` at 120 Hz; print when ``out_name`` is read; then its receive log."""
    import pylsl

    from cogblocks.data.groups import TABLE2

    omega = np.asarray(TABLE2[1].omega)
    info = pylsl.StreamInfo(in_name, "Phase", len(omega), 1 / PEER_DT, pylsl.cf_double64, f"{in_name}-peer")
    channels = info.desc().append_child("channels")
    for _ in omega:
        channels.append_child("channel").append_child_value("unit", "rad")
    outlet = pylsl.StreamOutlet(info)
    stop = threading.Event()

    def stream() -> None:
        start, k = time.perf_counter(), 0
        while not stop.is_set():
            stamp = pylsl.local_clock()
            outlet.push_sample(np.mod(omega * stamp, 2 * np.pi), stamp)
            k += 1
            time.sleep(max(0.0, start + k * PEER_DT - time.perf_counter()))

    threading.Thread(target=stream, daemon=True).start()
    found = pylsl.resolve_byprop("name", out_name, timeout=60.0)
    reader = pylsl.StreamInlet(found[0], max_buflen=10)
    reader.open_stream(10.0)
    print("ready", flush=True)
    stamps, received = [], []
    deadline = time.monotonic() + seconds + 60.0
    while time.monotonic() < deadline:
        _, stamp = reader.pull_sample(timeout=2.0)
        if stamp is None:
            if stamps:
                break
            continue
        received.append(pylsl.local_clock())
        stamps.append(stamp)
    stop.set()
    print(json.dumps({"stamps": stamps, "received": received}), flush=True)


def _live_run(seconds: float, load: bool, tag: str) -> dict:
    from cogblocks.live import live_sync, run_realtime

    in_name, out_name = f"bench-phases-{tag}", f"bench-theta-l2-{tag}"
    peer = subprocess.Popen(
        [sys.executable, "-m", "benchmarks.live", "--peer", in_name, out_name, str(seconds)],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        text=True,
    )
    busy = subprocess.Popen([sys.executable, "-c", "while True: pass"]) if load else None
    try:
        compiled = live_sync(in_name, out_name, group=1, motion="dqn", timeout=30.0).compile(DT)
        assert peer.stdout.readline().strip() == "ready", "the peer did not subscribe"
        report = run_realtime(compiled, seconds, 1.0 / DT, record=True)
        offline_ms = _offline_steps(compiled, report.trace["sample"])
        for block in compiled.blocks.values():
            if hasattr(block, "close"):
                block.close()
        log = json.loads(peer.stdout.readline())
    finally:
        if busy is not None:
            busy.kill()
            busy.wait()
        peer.wait(timeout=120)
    trace = report.trace
    stamps, received = np.array(log["stamps"]), np.array(log["received"])
    if len(stamps) != report.ticks:
        raise RuntimeError(f"the peer read {len(stamps)} outputs of {report.ticks} ticks")
    # the value behind tick k stands for the stream age_ms before the tick, which stamped its output
    fresh = trace["fresh"].astype(bool) & np.isfinite(trace["age_ms"])
    latency_ms = 1e3 * (received - stamps)[fresh] + trace["age_ms"][fresh]
    return {"report": report, "offline_ms": offline_ms, "latency_ms": latency_ms}


def _offline_steps(compiled, samples: np.ndarray) -> np.ndarray:
    """Step times of the diagram's L2 block back to back, fed the samples the live run received."""
    from cogblocks.blocks import Playback
    from cogblocks.data.groups import TABLE2
    from cogblocks.diagrams.sync import MOTIONS
    from cogblocks.sim import Diagram
    from cogblocks.sync import L2Sync

    group = TABLE2[1]
    d = Diagram()
    src = d.add("src", Playback(samples, unit="rad", wrapped=True))
    arch = d.add("arch", L2Sync(MOTIONS["dqn"](group), group.assisted))
    d.connect(src.y, arch.theta)
    d.expose_output("theta_l2", arch.theta_l2)
    offline = d.compile(DT)
    times = np.empty(len(samples))
    for k in range(len(samples)):
        start = time.perf_counter()
        offline.step()
        times[k] = time.perf_counter() - start
    return 1e3 * times


class _SampleTimes(Block):
    """Note, each tick, the stream time that an inlet's value stands for."""

    def __init__(self, inlet: Block) -> None:
        super().__init__()
        self.inlet = inlet
        self.add_input("u", unit=None)
        self.times: list[float] = []

    def output(self, k: int) -> None:
        self.times.append(self.inlet.sample_time)


def _phase_error(mode: str, seconds: float) -> float:
    """Mean phase error of the live phase diagram with its inlet in ``mode``, on a 1 Hz sine at 100 Hz."""
    import pylsl

    from cogblocks.live import live_phase, run_realtime

    name = f"bench-arm-{mode}"
    info = pylsl.StreamInfo(name, "MoCap", 1, 100.0, pylsl.cf_double64, f"{name}-src")
    info.desc().append_child("channels").append_child("channel").append_child_value("unit", "mm")
    outlet = pylsl.StreamOutlet(info)
    stop = threading.Event()

    def stream() -> None:
        start, k = time.perf_counter(), 0
        while not stop.is_set():
            stamp = pylsl.local_clock()
            outlet.push_sample([150.0 * np.cos(2 * np.pi * stamp)], stamp)
            k += 1
            time.sleep(max(0.0, start + k * DT - time.perf_counter()))

    threading.Thread(target=stream, daemon=True).start()
    try:
        d = live_phase(name, f"bench-phase-{mode}")
        d["inlet"].mode = mode
        times = d.add("times", _SampleTimes(d["inlet"]))
        d.connect(d["inlet"].y, times.u)
        report = run_realtime(d.compile(DT), seconds, 1.0 / DT, record=True)
    finally:
        stop.set()
    error = np.angle(np.exp(1j * (report.trace["theta"] - 2 * np.pi * np.array(times.times))))
    return float(np.mean(np.abs(error[300:])))  # once the estimator has seen three periods


def run(quick: bool = False) -> Iterator[dict]:
    """Yield the phase error by inlet mode, and the live pacing and latency figures of the sync diagram."""
    if "pylsl" not in sys.modules:
        use_machine_only_config(f"cogblocks-bench-{time.time_ns()}")
    elif "LSLAPICFG" not in os.environ:
        raise RuntimeError("benchmarks.live: pylsl is loaded without an lsl_api.cfg; run it in its own process")
    seconds = 10.0 if quick else 60.0
    phase_seconds = 8.0 if quick else 30.0
    busy = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        errors = {mode: _phase_error(mode, phase_seconds) for mode in ("interpolate", "latest")}
    finally:
        busy.kill()
        busy.wait()
    yield {
        "name": "live.phase.interpolate_error_rad",
        "value": errors["interpolate"],
        "unit": "rad",
        "reference": errors["latest"],
        "ratio": errors["interpolate"] / errors["latest"],
        "seconds": phase_seconds,
        "load": "one busy core",
    }
    loaded = _live_run(seconds, load=True, tag="loaded")
    clean = _live_run(seconds, load=False, tag="clean")
    rep, ref = loaded["report"], clean["report"]
    context = {"seconds": seconds, "ticks": rep.ticks, "load": "one busy core"}
    late_ref = max(ref.late_ticks, 1) / ref.ticks
    yield {
        "name": "live.sync.late_share",
        "value": rep.late_ticks / rep.ticks,
        "unit": "1",
        "reference": late_ref,
        "ratio": (rep.late_ticks / rep.ticks) / late_ref,
        **context,
        "late_ticks": rep.late_ticks,
        "overruns": rep.overruns,
        "unloaded_late_ticks": ref.late_ticks,
    }
    p99 = float(np.percentile(rep.tick_ms, 99))
    yield {
        "name": "live.sync.tick_ms_p99",
        "value": p99,
        "unit": "ms",
        "reference": BUDGET_MS,
        "ratio": p99 / BUDGET_MS,
        **context,
        "tick_ms_p50": float(np.median(rep.tick_ms)),
        "unloaded_tick_ms_p99": float(np.percentile(ref.tick_ms, 99)),
    }
    offline = float(np.percentile(loaded["offline_ms"], 99))
    yield {
        "name": "live.sync.offline_step_ms_p99",
        "value": offline,
        "unit": "ms",
        "reference": BUDGET_MS,
        "ratio": offline / BUDGET_MS,
        **context,
        "live_tick_over_offline": p99 / offline,
    }
    for q in (50, 99):
        latency = float(np.percentile(loaded["latency_ms"], q))
        yield {
            "name": f"live.sync.latency_ms_p{q}",
            "value": latency,
            "unit": "ms",
            "reference": 1e3 * DT,
            "ratio": latency / (1e3 * DT),
            **context,
            "fresh_ticks": len(loaded["latency_ms"]),
            f"unloaded_latency_ms_p{q}": float(np.percentile(clean["latency_ms"], q)),
        }


if __name__ == "__main__":  # python -m benchmarks.live [--quick], or the peer process
    if len(sys.argv) == 5 and sys.argv[1] == "--peer":
        _peer(sys.argv[2], sys.argv[3], float(sys.argv[4]))
    else:
        for line in run(quick="--quick" in sys.argv):
            print(json.dumps(line), flush=True)
