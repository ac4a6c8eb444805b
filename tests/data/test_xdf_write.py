"""The XDF writer, read back with pyxdf: values, time stamps, clock offsets, several streams and formats."""

import os

import numpy as np
import pytest

pyxdf = pytest.importorskip("pyxdf", reason="the recordings extra (pyxdf) is not installed")

from cogblocks.data.xdf_write import RecordingError, XDFStream, write_xdf  # noqa: E402


def _streams(rng):
    t = 1000.0 + np.cumsum(rng.uniform(0.005, 0.015, 2500))  # more samples than one chunk holds
    return [
        XDFStream(
            "Arm",
            "MoCap",
            t,
            rng.normal(size=(2500, 3)) * 1e3,
            nominal_srate=100.0,
            labels=["x", "y", "z"],
            units=["m", "m", "m"],
            source_id="arm-1",
            clock_offsets=[(1000.0, 0.25), (1010.0, 0.5)],
        ),
        XDFStream("Gain", "Misc", t[:300], rng.normal(size=(300, 2)).astype(np.float32), channel_format="float32"),
        XDFStream("Count", "Misc", t[:10], np.arange(-5, 5).reshape(10, 1), channel_format="int16", units=["1"]),
        XDFStream("Markers", "Markers", t[:3], [["start"], ["<b> & é"], ["end"]], channel_format="string"),
        XDFStream("Empty", "Misc", np.empty(0), np.empty((0, 2)), labels=["a", "b"]),
    ]


def test_pyxdf_reads_back_every_stream_as_written(tmp_path):
    streams = _streams(np.random.default_rng(1))
    path = write_xdf(tmp_path / "s.xdf", streams)
    got, header = pyxdf.load_xdf(str(path), synchronize_clocks=False, dejitter_timestamps=False)
    assert header["info"]["version"] == ["1.0"]
    assert [s["info"]["name"][0] for s in got] == ["Arm", "Gain", "Count", "Markers", "Empty"]
    arm, gain, count, markers, empty = got
    np.testing.assert_array_equal(arm["time_stamps"], streams[0].stamps)  # bit for bit
    np.testing.assert_array_equal(arm["time_series"], streams[0].values)
    assert arm["time_series"].dtype == np.float64 and gain["time_series"].dtype == np.float32
    np.testing.assert_array_equal(gain["time_series"], streams[1].values)
    np.testing.assert_array_equal(count["time_series"], np.arange(-5, 5).reshape(10, 1))
    assert count["time_series"].dtype == np.int16
    assert markers["time_series"] == [["start"], ["<b> & é"], ["end"]]
    assert len(empty["time_stamps"]) == 0
    assert (arm["clock_times"], arm["clock_values"]) == ([1000.0, 1010.0], [0.25, 0.5])
    info = arm["info"]
    assert (info["type"], info["channel_count"], info["nominal_srate"], info["source_id"]) == (
        ["MoCap"],
        ["3"],
        ["100.0"],
        ["arm-1"],
    )
    channels = info["desc"][0]["channels"][0]["channel"]
    assert [(c["label"][0], c["unit"][0]) for c in channels] == [("x", "m"), ("y", "m"), ("z", "m")]
    assert arm["footer"]["info"]["sample_count"] == ["2500"]


def test_pyxdf_applies_the_clock_offsets(tmp_path):
    stream = _streams(np.random.default_rng(2))[0]
    path = write_xdf(tmp_path / "s.xdf", [stream])
    (got,), _ = pyxdf.load_xdf(str(path), dejitter_timestamps=False)
    # pyxdf fits the offsets linearly against their collection times: 0.25 at 1000 s, 0.5 at 1010 s
    expected = stream.stamps + 0.25 + 0.025 * (stream.stamps - 1000.0)
    np.testing.assert_allclose(got["time_stamps"], expected, atol=1e-9)


def test_a_failed_write_keeps_the_recording_in_a_temporary_file(tmp_path):
    streams = _streams(np.random.default_rng(3))
    target = tmp_path / "gone" / "s.xdf"  # the folder went away during the run
    with pytest.raises(RecordingError, match=rf"could not write the recording to {target} .*it was written to ") as e:
        write_xdf(target, streams)
    try:
        (arm, *_), _ = pyxdf.load_xdf(str(e.value.saved), synchronize_clocks=False)
        np.testing.assert_array_equal(arm["time_series"], streams[0].values)
    finally:
        os.unlink(e.value.saved)
    assert not target.parent.exists()


def test_a_complete_file_replaces_the_old_one_and_no_partial_file_is_left(tmp_path):
    path = tmp_path / "s.xdf"
    path.write_bytes(b"old")
    write_xdf(path, _streams(np.random.default_rng(4))[:1])
    assert path.read_bytes()[:4] == b"XDF:" and sorted(p.name for p in tmp_path.iterdir()) == ["s.xdf"]


def test_an_unknown_channel_format_is_refused_before_anything_is_written(tmp_path):
    (tmp_path / "d.xdf").mkdir()
    with pytest.raises(ValueError, match="write_xdf: stream 'x' has channel_format 'float16'"):
        write_xdf(tmp_path / "a.xdf", [XDFStream("x", "y", np.zeros(1), np.zeros((1, 1)), channel_format="float16")])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.xdf"]  # nor a partial file
