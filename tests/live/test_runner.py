"""run_realtime: deadline pacing, late ticks and overruns, and the ready diagrams run live on real LSL streams."""

import time

import numpy as np
import pytest

from cogblocks.sim import Block, Diagram


class _Stall(Block):
    """Output the tick number, note when each tick ran, and stall once for ``seconds``."""

    def __init__(self, at: int, seconds: float) -> None:
        super().__init__()
        self.at, self.seconds = at, seconds
        self.add_output("k", unit="1")
        self.ran: list[float] = []

    def output(self, k: int) -> None:
        self.ran.append(time.perf_counter())
        if k == self.at:
            time.sleep(self.seconds)
        self.k.value[...] = k


def _stall_diagram(at=20, seconds=0.035):
    d = Diagram()
    stall = d.add("stall", _Stall(at, seconds))
    d.expose_output("k", stall.k)
    return d.compile(0.01), stall


def test_ticks_keep_their_deadlines_after_a_stall():
    from cogblocks.live import run_realtime

    compiled, stall = _stall_diagram()
    report = run_realtime(compiled, 0.6, record=True)
    ran = np.array(stall.ran)
    assert report.ticks == 60 and len(ran) == 60 and not report.interrupted
    # no tick starts before its deadline (the runner's start is at most the first tick's start)
    assert np.all(report.start_ms >= 0)
    assert np.all(ran - ran[0] >= 0.01 * np.arange(60) - report.start_ms[0] / 1e3 - 1e-4)
    # the stall costs three deadlines: the ticks behind it run back to back, then the schedule is the old one
    assert report.tick_ms[20] >= 35.0 and report.overruns >= 1 and report.late_ticks >= 3
    assert ran[21] - ran[20] >= 0.035 and ran[22] - ran[21] < 0.01
    # delays only add, so the earliest tick shows where the schedule is: a sleep-per-tick pacer would be
    # 35 ms behind from here on
    drift = ran[30:] - ran[0] - 0.01 * np.arange(30, 60)
    assert np.min(drift) < 0.005
    np.testing.assert_array_equal(report.trace["k"], np.arange(60))
    np.testing.assert_allclose(report.trace.t, 0.01 * np.arange(60))
    summary = report.summary()
    assert set(summary) == {
        "ticks",
        "late_ticks",
        "tick_ms_p50",
        "tick_ms_p99",
        "samples_in",
        "samples_out",
        "max_age_ms",
    }
    assert summary["tick_ms_p50"] == pytest.approx(np.median(report.tick_ms))
    assert summary["samples_in"] == summary["samples_out"] == 0 and np.isnan(summary["max_age_ms"])


def test_the_runner_refuses_what_it_cannot_pace():
    from cogblocks.blocks import Gain
    from cogblocks.live import run_realtime
    from cogblocks.sim import Signal

    compiled, _ = _stall_diagram()
    with pytest.raises(ValueError, match=r"compiled with dt = 0.01 s, which does not tick at 50 Hz"):
        run_realtime(compiled, 1.0, rate=50)
    with pytest.raises(ValueError, match="duration must be a positive number of seconds, got 0"):
        run_realtime(compiled, 0)
    d = Diagram()
    gain = d.add("gain", Gain(2.0))
    d.expose_input("u", gain.u, spec=Signal())
    with pytest.raises(ValueError, match=r"top-level inputs \['u'\]; a live diagram takes its inputs from inlet"):
        run_realtime(d.compile(0.01), 1.0)


def _published(lsl, name):
    """A test inlet on the stream ``name``, opened before the run."""
    found = lsl.resolve_byprop("name", name, timeout=5.0)
    assert found, f"the diagram did not publish {name!r}"
    reader = lsl.StreamInlet(found[0], max_buflen=60)
    reader.open_stream(5.0)
    return reader


def _drain(reader, expected):
    samples, stamps = [], []
    deadline = time.monotonic() + 2.0
    while len(stamps) < expected and time.monotonic() < deadline:
        chunk, ts = reader.pull_chunk(timeout=0.05)
        samples += chunk
        stamps += ts
    return np.array(samples), np.array(stamps)


def _offline(arch_port, arch, data, unit, wrapped=False):
    """The architecture block fed the recorded inlet samples, tick by tick, without any network."""
    from cogblocks.blocks import Playback

    d = Diagram()
    src = d.add("src", Playback(data, unit=unit, wrapped=wrapped))
    d.add("arch", arch)
    d.connect(src.y, getattr(arch, arch_port[0]))
    d.expose_output("y", getattr(arch, arch_port[1]))
    compiled = d.compile(0.01)
    return np.array([compiled.step()["y"] for _ in range(len(data))])


def _live_blender():
    """A fresh blender like the one ``live_sync`` puts behind its motion computer by default."""
    from cogblocks.diagrams.sync import DEFAULT_BLENDER
    from cogblocks.sync import Blender
    from cogblocks.sync.blending import blender_params

    return Blender(params=blender_params("offline", DEFAULT_BLENDER))


def test_the_phase_diagram_tracks_a_sine_streamed_at_100_hz(lsl, streamer, stream_name):
    from cogblocks.live import live_phase, run_realtime
    from cogblocks.phase import PhaseEstimator

    freq, amp = 1.0, 150.0
    source = streamer(f"{stream_name}-arm", lambda t: amp * np.cos(2 * np.pi * freq * t))
    compiled = live_phase(f"{stream_name}-arm", f"{stream_name}-phase").compile(0.01)
    reader = _published(lsl, f"{stream_name}-phase")
    report = run_realtime(compiled, 4.0, record=True, record_raw=True)
    theta, stamps = _drain(reader, report.ticks)
    trace = report.trace
    # every tick published its phase, stamped when it ran, and the test inlet read exactly those values
    assert report.samples_out == report.ticks == len(theta) == 400
    np.testing.assert_array_equal(theta[:, 0], trace["theta"])
    assert np.all(np.diff(stamps) > 0) and np.median(np.diff(stamps)) == pytest.approx(0.01, abs=5e-4)
    # the raw samples are the sine at their (clock-corrected) stamps, and the ticks used them as they came
    t_raw, x_raw = report.raw["inlet"]
    assert len(t_raw) == report.samples_in >= 350
    np.testing.assert_allclose(x_raw, amp * np.cos(2 * np.pi * freq * t_raw), atol=0.05)
    assert np.count_nonzero(trace["fresh"]) >= 200 and report.max_age_ms == np.max(
        trace["age_ms"][np.isfinite(trace["age_ms"])]
    )
    # error against the true phase of the sample each tick used (published stamp minus the sample's age)
    sampled = stamps - 1e-3 * trace["age_ms"]
    true = np.mod(2 * np.pi * freq * sampled, 2 * np.pi)
    error = np.abs(np.angle(np.exp(1j * (theta[:, 0] - true))))
    # once the estimator has seen two periods (measured here: mean 0.01-0.03 rad); the 95th percentile,
    # as a tick held up for long on a loaded machine starts a new interpolation grid
    mean, p95 = np.mean(error[200:]), np.percentile(error[200:], 95)
    assert mean < 0.06 and p95 < 0.15, f"phase error mean {mean:.3f} rad, 95th percentile {p95:.3f} rad"
    # the live run is the offline diagram fed the same samples
    offline = _offline(("p", "theta"), PhaseEstimator(unit="mm"), trace["sample"], "mm")
    np.testing.assert_allclose(offline, trace["theta"], rtol=0, atol=1e-12)
    del source


def test_sync_and_l1_run_live_as_they_run_offline(lsl, streamer, stream_name):
    from cogblocks.data.groups import TABLE2
    from cogblocks.diagrams.sync import MOTIONS
    from cogblocks.live import live_l1, live_sync, run_realtime
    from cogblocks.live.ready import LAG
    from cogblocks.sensing import L1, KalmanEstimator
    from cogblocks.sync import L2Sync

    group = TABLE2[1]
    omega = np.asarray(group.omega)
    streamer(f"{stream_name}-phases", lambda t: np.mod(omega * t, 2 * np.pi), channels=group.n, unit="rad")
    streamer(f"{stream_name}-marker", lambda t: 100.0 * np.sin(2 * np.pi * np.array([0.5, 0.7, 0.9]) * t), 3)
    sync = live_sync(f"{stream_name}-phases", f"{stream_name}-theta-l2", group=1, motion="dqn").compile(0.01)
    l1 = live_l1(f"{stream_name}-marker", f"{stream_name}-avatar", delay=0.1).compile(0.01)
    for compiled in (sync, l1):
        report = run_realtime(compiled, 0.5, record=True)
        assert report.ticks == report.samples_out == 50 and report.samples_in >= 40
        assert np.all(np.isfinite(report.trace["sample"][5:]))
        if compiled is sync:
            arch = L2Sync(MOTIONS["dqn"](group), group.assisted, _live_blender())
            offline = _offline(("theta", "theta_l2"), arch, report.trace["sample"], "rad", wrapped=True)
            np.testing.assert_allclose(offline, report.trace["theta_l2"], rtol=0, atol=1e-12)
        else:
            arch = L1(0.1 + LAG, estimator=KalmanEstimator("ca", dims=3))
            offline = _offline(("p", "p_avatar"), arch, report.trace["sample"], "mm")
            np.testing.assert_allclose(offline, report.trace["p_avatar"], rtol=0, atol=1e-9, equal_nan=True)


@pytest.mark.realtime
def test_replan_decides_on_its_thread_live_and_plays_what_it_would_offline(
    lsl, streamer, stream_name, replayed_planner
):
    from cogblocks.data.groups import TABLE2
    from cogblocks.live import live_sync, run_realtime
    from cogblocks.sync import L2Sync, RecedingPlanMotion

    group = TABLE2[1]
    omega = np.asarray(group.omega)
    streamer(f"{stream_name}-phases", lambda t: np.mod(omega * t, 2 * np.pi), channels=group.n, unit="rad")
    sync = live_sync(f"{stream_name}-phases", f"{stream_name}-theta-l2", group=1, motion="replan").compile(0.01)
    (block,) = [b for b in sync.blocks.values() if isinstance(b, RecedingPlanMotion)]
    assert block.worker == "thread" and block.end is None
    report = run_realtime(sync, 3.0, record=True)
    block.close()
    assert report.ticks == report.samples_out == 300
    # decisions from the 50th good increment; a decision's plan starts a period (100 ticks) after it, if taken
    # before then, and is dropped as late otherwise (the run's last tick, 299, puts in force a plan of tick 300)
    assert block.timeline, "no decision started"
    due = [(s + 100, t) for s, t in block.timeline if s + 100 <= 300]
    assert [start for start, _, _ in block.plans] == [start for start, t in due if 0 <= t < start]
    assert block.late == sum(t < 0 or t >= start for start, t in due)
    # the same samples offline, its decisions taken at the ticks the thread's were: the same plans, the same θ_L2
    offline_block = replayed_planner(block.timeline, group.n, group.assisted, adjacency=group.graph, end=None)
    offline = _offline(
        ("theta", "theta_l2"),
        L2Sync(offline_block, group.assisted, _live_blender()),
        report.trace["sample"],
        "rad",
        wrapped=True,
    )
    np.testing.assert_allclose(offline, report.trace["theta_l2"], rtol=0, atol=1e-12)
    assert [p[0] for p in offline_block.plans] == [p[0] for p in block.plans] and offline_block.late == block.late
    assert offline_block.timeline == block.timeline


@pytest.mark.realtime
def test_gated_runs_the_threaded_planner_behind_the_gate_live_and_plays_what_it_would_offline(
    lsl, streamer, stream_name, replayed_planner
):
    from cogblocks.data.groups import TABLE2
    from cogblocks.live import live_sync, run_realtime
    from cogblocks.sync import GatedMotion, L2Sync, RecedingPlanMotion
    from cogblocks.sync.gated import NoiseGate

    group = TABLE2[1]
    omega = np.asarray(group.omega)
    streamer(f"{stream_name}-phases", lambda t: np.mod(omega * t, 2 * np.pi), channels=group.n, unit="rad")
    sync = live_sync(f"{stream_name}-phases", f"{stream_name}-theta-l2", group=1, motion="gated").compile(0.01)
    (planner,) = [b for b in sync.blocks.values() if isinstance(b, RecedingPlanMotion)]
    (gate,) = [b for b in sync.blocks.values() if isinstance(b, NoiseGate)]
    assert planner.worker == "thread" and planner.end is None
    report = run_realtime(sync, 3.0, record=True)
    planner.close()
    assert report.ticks == report.samples_out == 300
    # decided after its first second (the stream's timing jitter may well look like noise to it)
    assert gate.world in ("model", "noisy") and np.isfinite(gate.sigma_hat) and planner.timeline
    # the same samples offline, the planner replaying its thread's timeline behind its own gate: the same θ_L2
    offline_planner = replayed_planner(planner.timeline, group.n, group.assisted, adjacency=group.graph, end=None)
    offline_gated = GatedMotion(offline_planner)
    offline = _offline(
        ("theta", "theta_l2"),
        L2Sync(offline_gated, group.assisted, _live_blender()),
        report.trace["sample"],
        "rad",
        wrapped=True,
    )
    np.testing.assert_allclose(offline, report.trace["theta_l2"], rtol=0, atol=1e-12)
    assert offline_gated.world == gate.world and offline_gated.sigma_hat == gate.sigma_hat, gate.sigma_hat
    assert [p[0] for p in offline_planner.plans] == [p[0] for p in planner.plans]
    assert offline_planner.late == planner.late and offline_planner.timeline == planner.timeline
