"""``cogblocks view`` on an XDF file that other programs recorded (LabRecorder): every numeric stream on one grid."""

import numpy as np
import pytest

pyxdf = pytest.importorskip("pyxdf", reason="the recordings extra (pyxdf) is not installed")

from cogblocks.data.xdf_write import XDFStream, write_xdf  # noqa: E402
from cogblocks.live.view import load_run  # noqa: E402


def _labrecorder_file(path):
    """A tracker on a clock 100 s behind the recorder's (its offsets say so), an EEG, events, a dead stream."""
    arm_true = 10.0 + np.arange(600) / 120.0  # 5 s at 120 Hz, from 10 s on the recorder's clock
    eeg = 9.5 + np.arange(1500) / 250.0  # 6 s at 250 Hz
    arm = 0.2 * np.column_stack([np.sin(np.pi * arm_true), np.cos(np.pi * arm_true), np.sin(2 * np.pi * arm_true)])
    write_xdf(
        path,
        [
            XDFStream("Arm", "MoCap", arm_true - 100.0, arm, nominal_srate=120.0, labels=list("xyz"),
                      units=["m"] * 3, clock_offsets=[(-90.0, 100.0), (-85.0, 100.0)]),
            XDFStream("EEG", "EEG", eeg, np.cos(2 * np.pi * eeg)[:, None], nominal_srate=250.0,
                      clock_offsets=[(9.5, 0.0), (15.5, 0.0)]),
            XDFStream("Events", "Markers", np.array([11.0, 13.0]), [["with L2"], ["without"]], channel_format="string"),
            XDFStream("Glove", "Misc", np.empty(0), np.empty((0, 2)), labels=["a", "b"]),
        ],
    )  # fmt: skip
    return arm_true, arm, eeg


def test_every_numeric_stream_on_one_grid_and_the_rest_named(tmp_path):
    arm_true, arm, eeg = _labrecorder_file(tmp_path / "lab.xdf")
    skipped = []
    t, signals, units, late = load_run(tmp_path / "lab.xdf", skipped)
    assert set(signals) == {"Arm", "EEG"} and units == {"Arm": "m", "EEG": ""} and not late.any()
    np.testing.assert_allclose(np.diff(t), 0.01, atol=1e-9)
    now = 9.5 + t  # the grid on the recorder's clock: from the first sample of any stream
    inside = (now >= arm_true[0]) & (now <= arm_true[-1])
    assert np.isnan(signals["Arm"][~inside]).all() and signals["Arm"].shape == (len(t), 3)
    expected = 0.2 * np.column_stack([np.sin(np.pi * now), np.cos(np.pi * now), np.sin(2 * np.pi * now)])[inside]
    np.testing.assert_allclose(signals["Arm"][inside], expected, atol=1e-3)  # the offset applied, interpolated
    np.testing.assert_allclose(signals["EEG"][now <= eeg[-1], 0], np.cos(2 * np.pi * now[now <= eeg[-1]]), atol=1e-3)
    assert any("'Events': text (2 samples)" in line for line in skipped)
    assert any("'Glove': 0 sample(s)" in line for line in skipped)


def test_a_file_with_nothing_to_draw_is_named(tmp_path):
    write_xdf(tmp_path / "events.xdf", [XDFStream("E", "Markers", np.array([1.0]), [["go"]], channel_format="string")])
    with pytest.raises(ValueError, match=r"events\.xdf: no stream of numbers to show \(stream 'E': text"):
        load_run(tmp_path / "events.xdf")


def test_view_serves_a_labrecorder_file_and_says_what_it_leaves_out(tmp_path, view_server):
    _labrecorder_file(tmp_path / "lab.xdf")
    view = view_server(tmp_path / "lab.xdf")
    assert view.line.startswith(f"view of {tmp_path / 'lab.xdf'} at http://127.0.0.1:"), view.line
    assert sorted(p["series"] for p in view.get("meta")["panels"]) == [["Arm"], ["EEG"], ["late"]]
    code, err = view.stop()
    assert code == 0, err
    assert "cogblocks view: not shown: stream 'Events': text" in err and "stream 'Glove'" in err
