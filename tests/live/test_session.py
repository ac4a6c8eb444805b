"""Record a live run over LSL (loopback) as an XDF session, read it with pyxdf, replay it tick for tick."""

import numpy as np
import pytest

pyxdf = pytest.importorskip("pyxdf", reason="the recordings extra (pyxdf) is not installed")


def _live(lsl, streamer, stream_name, build, signal, channels, unit, seconds=2.0):
    from cogblocks.live import run_realtime
    from cogblocks.live.session import enable_recording

    source = streamer(f"{stream_name}-in", signal, channels=channels, unit=unit)
    compiled = build(f"{stream_name}-in", f"{stream_name}-out").compile(0.01)
    enable_recording(compiled)
    report = run_realtime(compiled, seconds, record=True)
    for block in compiled.blocks.values():
        if hasattr(block, "close"):
            block.close()
    return compiled, report, source


def test_a_recorded_phase_session_reads_back_and_replays_bit_for_bit(lsl, streamer, stream_name, tmp_path):
    from cogblocks.live import live_phase
    from cogblocks.live.replay import load_session, replay_session
    from cogblocks.live.session import write_session

    def arm(t):
        return 0.15 * np.cos(2 * np.pi * 0.8 * t)  # metres: the inlet converts to the estimator's mm

    compiled, report, source = _live(lsl, streamer, stream_name, live_phase, arm, 1, "m")
    options = {"diagram": "phase", "in": f"{stream_name}-in", "out": f"{stream_name}-out"}
    path = write_session(tmp_path / "s.xdf", compiled, report, options)

    streams, _ = pyxdf.load_xdf(str(path), synchronize_clocks=False, dejitter_timestamps=False)
    by_name = {s["info"]["name"][0]: s for s in streams}
    assert set(by_name) == {f"{stream_name}-in", f"{stream_name}-out", "inlet ticks", "cogblocks run"}
    recorded_in, recorded_out = by_name[f"{stream_name}-in"], by_name[f"{stream_name}-out"]
    # what the inlet received, as the sender stamped and sent it (metres, the sender's unit and labels)
    inlet = compiled.blocks["inlet"]
    assert len(recorded_in["time_stamps"]) == inlet.samples_in == report.samples_in > 150
    sent = np.array(source.stamps)
    first = int(np.searchsorted(sent, recorded_in["time_stamps"][0]))
    np.testing.assert_array_equal(recorded_in["time_stamps"], sent[first : first + inlet.samples_in])
    np.testing.assert_array_equal(recorded_in["time_series"][:, 0], arm(recorded_in["time_stamps"]))
    channels = recorded_in["info"]["desc"][0]["channels"][0]["channel"]
    assert [(c["label"][0], c["unit"][0]) for c in channels] == [("c0", "m")]
    assert recorded_in["clock_values"] == [0.0]  # a stream of this machine: no correction
    # what the outlet published: θ at every tick, in rad
    np.testing.assert_array_equal(recorded_out["time_series"][:, 0], report.trace["theta"])
    assert recorded_out["info"]["desc"][0]["channels"][0]["channel"][0]["unit"] == ["rad"]
    assert len(by_name["cogblocks run"]["time_stamps"]) == report.ticks == 200

    session = load_session(path)
    assert session.options == options and session.dt == 0.01
    replayed = replay_session(live_phase(f"{stream_name}-in", f"{stream_name}-out"), session)
    assert replayed.ticks == report.ticks and replayed.samples_in == report.samples_in
    assert replayed.late_ticks == report.late_ticks
    for name in ("theta", "sample", "age_ms", "fresh"):
        np.testing.assert_array_equal(replayed.trace[name], report.trace[name], err_msg=name)
    assert replayed.max_age_ms == report.max_age_ms
    # cogblocks view shows a session through the same replay: the live run's every output and its late ticks
    from cogblocks.live.view import load_run

    t, signals, units, late = load_run(path)
    np.testing.assert_array_equal(t, report.trace.t)
    np.testing.assert_array_equal(signals["theta"], report.trace["theta"])
    assert units["theta"] == "rad" and late.sum() == report.late_ticks
    # the replay saw the stream in mm, as the live run did
    finite = np.isfinite(report.trace["sample"])
    assert finite.sum() > 150 and np.nanmax(np.abs(report.trace["sample"])) == pytest.approx(150.0, abs=1.0)


def test_a_sync_session_replays_on_three_wrapped_channels(lsl, streamer, stream_name, tmp_path):
    from cogblocks.data.groups import TABLE2
    from cogblocks.live import live_sync
    from cogblocks.live.replay import load_session, replay_session
    from cogblocks.live.session import write_session

    omega = np.asarray(TABLE2[1].omega)

    def build(i, o):
        return live_sync(i, o, group=1, motion="mean")

    compiled, report, _ = _live(
        lsl, streamer, stream_name, build, lambda t: np.mod(omega * t, 2 * np.pi), TABLE2[1].n, "rad", 1.5
    )
    path = write_session(tmp_path / "s.xdf", compiled, report)
    replayed = replay_session(build(f"{stream_name}-in", f"{stream_name}-out"), load_session(path))
    for name in ("theta_l2", "sample", "age_ms"):
        np.testing.assert_array_equal(replayed.trace[name], report.trace[name], err_msg=name)


def test_a_file_that_is_not_a_session_is_named(tmp_path):
    from cogblocks.data.xdf_write import XDFStream, write_xdf
    from cogblocks.live.replay import load_session

    with pytest.raises(ValueError, match=r"nothing\.xdf: no such file"):
        load_session(tmp_path / "nothing.xdf")
    (tmp_path / "bad.xdf").write_bytes(b"not xdf at all")
    with pytest.raises(ValueError, match=r"bad\.xdf: not a readable XDF file"):
        load_session(tmp_path / "bad.xdf")
    plain = write_xdf(tmp_path / "plain.xdf", [XDFStream("a", "b", np.zeros(1), np.zeros((1, 1)))])
    with pytest.raises(ValueError, match=r"plain\.xdf: not a cogblocks session \(no 'cogblocks run' stream"):
        load_session(plain)


def test_a_session_written_as_the_run_goes_holds_what_the_finished_run_writes(lsl, streamer, stream_name, tmp_path):
    from cogblocks.live import live_phase, run_realtime
    from cogblocks.live.session import SessionRecorder, write_session

    streamer(f"{stream_name}-in", lambda t: 100.0 * np.sin(2 * np.pi * t))
    compiled = live_phase(f"{stream_name}-in", f"{stream_name}-out").compile(0.01)
    options = {"diagram": "phase", "in": f"{stream_name}-in", "out": f"{stream_name}-out"}
    recorder = SessionRecorder(tmp_path / "going.xdf", compiled, options, every=0.05)  # many small writes
    report = run_realtime(compiled, 1.5, record=True, recorder=recorder)
    assert recorder.close(report.interrupted) == tmp_path / "going.xdf"
    for block in compiled.blocks.values():
        if hasattr(block, "close"):
            block.close()
    write_session(tmp_path / "whole.xdf", compiled, report, options)
    read = [
        pyxdf.load_xdf(str(tmp_path / name), synchronize_clocks=False, dejitter_timestamps=False)[0]
        for name in ("going.xdf", "whole.xdf")
    ]
    assert [s["info"] for s in read[0]] == [s["info"] for s in read[1]]
    for going, whole in zip(*read, strict=True):
        name = going["info"]["name"][0]
        np.testing.assert_array_equal(going["time_stamps"], whole["time_stamps"], err_msg=name)
        np.testing.assert_array_equal(going["time_series"], whole["time_series"], err_msg=name)
        assert going["clock_values"] == whole["clock_values"] and going["footer"] == whole["footer"], name
    run = next(s for s in read[0] if s["info"]["name"][0] == "cogblocks run")
    assert len(run["time_stamps"]) == report.ticks == 150
    assert run["footer"]["info"]["cogblocks"][0]["interrupted"] == ["false"]
