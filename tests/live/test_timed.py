"""TimedInlet on a scripted stream of another clock: what is recorded, the offsets written, a replay to the bit."""

import numpy as np
import pytest

from cogblocks.live.timed import StreamHeader, TimedInlet
from cogblocks.sim import Diagram

pyxdf = pytest.importorskip("pyxdf", reason="the recordings extra (pyxdf) is not installed")


class Scripted(TimedInlet):
    """A stream whose clock runs 100 s behind ours, its offset re-measured (and drifting) every 10 ticks."""

    def __init__(self, **kw):
        super().__init__(shape=(2,), unit="mm", wrapped=False, source_unit=None, record=False, period=None, **kw)
        self.rng = np.random.default_rng(3)
        self.clock = 500.0
        self.ticks = 0

    def _open(self):
        header = StreamHeader("Scripted", "MoCap", 2, "float32", 100.0, "s-1", ["x", "y"], ["cm", "cm"], "peer")
        self.scale = self._check_stream(header)
        self.correction = 100.0
        return header

    def _clock(self):
        self.clock += 0.0003
        return self.clock

    def _refresh_correction(self):
        if self.ticks % 10 == 0:
            self.correction = 100.0 + 1e-4 * self.ticks
        self.ticks += 1
        self.clock += 0.01 - 0.0006

    def _receive(self):
        n = int(self.rng.integers(0, 3))  # 0, 1 or 2 samples a tick: irregular arrival
        if n == 0:
            return []
        stamps = self.clock - self.correction - 0.004 * np.arange(n)[::-1]
        values = self.rng.normal(size=(n, 2)).astype(np.float32)
        return [(stamps, values)]


def _diagram(**kw):
    d = Diagram()
    inlet = d.add("inlet", Scripted(**kw))
    d.expose_output("y", inlet.y)
    d.expose_output("age_ms", inlet.age_ms)
    return d


@pytest.mark.parametrize("mode", ["latest", "interpolate"])
def test_a_stream_of_another_clock_records_its_offsets_and_replays_to_the_bit(mode, tmp_path):
    from cogblocks.live import load_session, replay_session, write_session
    from cogblocks.live.runner import RealtimeReport, _trace
    from cogblocks.live.session import enable_recording

    compiled = _diagram(mode=mode, lag=0.015, hold=0.05).compile(0.01)
    enable_recording(compiled)
    rows = [compiled.step() for _ in range(80)]
    report = RealtimeReport(80, 0, 0, np.ones(80), np.zeros(80), 0, 0, np.nan, trace=_trace(rows, compiled, 0))
    inlet = compiled.blocks["inlet"]
    # raw(): stamps on our clock (the offset of each sample's tick added), values in mm
    t, x = inlet.raw()
    stamps, values, corrections = inlet._received()
    np.testing.assert_array_equal(t, stamps + corrections)
    np.testing.assert_array_equal(x, values.astype(np.float64) * 10.0)
    assert set(np.round(corrections - 100.0, 6)) == {1e-4 * k for k in range(0, 80, 10)}

    path = write_session(tmp_path / "s.xdf", compiled, report, {"what": "scripted"})
    (stream, *_), _ = pyxdf.load_xdf(str(path), synchronize_clocks=False, dejitter_timestamps=False)
    assert stream["info"]["name"] == ["Scripted"] and stream["time_series"].dtype == np.float32
    np.testing.assert_array_equal(stream["time_stamps"], stamps)  # the sender's clock, as received
    assert stream["clock_values"] == [100.0 + 1e-4 * k for k in range(0, 80, 10)]
    # collection times on the stream's clock, as LabRecorder writes them
    assert np.all(np.abs(np.array(stream["clock_times"]) - 400.0) < 1.0)
    # pyxdf's own synchronisation moves them onto our clock, close to what the inlet did
    (synced, *_), _ = pyxdf.load_xdf(str(path), dejitter_timestamps=False)
    np.testing.assert_allclose(synced["time_stamps"], t, atol=2e-3)

    session = load_session(path)
    assert session.options == {"what": "scripted"}
    again = replay_session(_diagram(mode=mode, lag=0.015, hold=0.05), session)
    for name in ("y", "age_ms"):
        np.testing.assert_array_equal(again.trace[name], report.trace[name], err_msg=name)
    assert np.isfinite(report.trace["y"]).mean() > 0.5


def test_a_replay_past_the_recording_is_refused(tmp_path):
    from cogblocks.live.replay import RecordedStream

    header = StreamHeader("S", "MoCap", 1, "double64", 100.0)
    recorded = RecordedStream(header, np.array([1.0]), np.array([[2.0]]), np.array([[1.0, 1.1, 1.0, 0.5]]))
    started, now, chunks, correction = recorded.tick()
    assert (started, now, correction) == (1.0, 1.1, 0.5) and chunks[0][1].tolist() == [[2.0]]
    with pytest.raises(IndexError, match="the recording of stream 'S' holds 1 ticks only"):
        recorded.tick()
