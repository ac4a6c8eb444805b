"""load_xdf_markers on XDF files written by write_xdf and read by pyxdf: both layouts, units, events, errors."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pyxdf")

from cogblocks.data.loaders import DataFormatError  # noqa: E402
from cogblocks.data.recordings import load_recording  # noqa: E402
from cogblocks.data.xdf import load_xdf_markers, write_xdf  # noqa: E402

T0 = 5000.0  # LSL clocks count from the machine's boot


def _circle(t: np.ndarray, phase: float) -> np.ndarray:
    """A 0.5 Hz circle of radius 200 mm in mm."""
    return np.column_stack([200 * np.cos(np.pi * t + phase), 200 * np.sin(np.pi * t + phase), 900 + 0 * t])


def test_a_stream_per_participant_in_its_own_unit_on_one_grid(tmp_path):
    t = np.arange(600) / 100.0
    streams = [
        {"name": "P1", "time_stamps": T0 + t, "time_series": _circle(t, 0.0), "labels": ["x", "y", "z"], "unit": "mm"},
        # started 4 ms later, in metres, its channels stored z, x, y
        {
            "name": "P2",
            "time_stamps": T0 + 0.004 + t,
            "time_series": _circle(t + 0.004, 1.0)[:, [2, 0, 1]] / 1000,
            "labels": ["z", "x", "y"],
            "unit": "meters",
        },
        {"name": "conditions", "time_stamps": np.array([T0 + 1.0, T0 + 3.0]), "time_series": ["without", "with"]},
    ]
    write_xdf(tmp_path / "group.xdf", streams)
    rec = load_xdf_markers(tmp_path / "group.xdf")
    assert rec.markers == ("P1", "P2") and rec.rate == pytest.approx(100.0)
    np.testing.assert_allclose(rec.t, 0.01 * np.arange(len(rec.t)), atol=1e-9)
    start = 0.004  # the grid starts when the later stream starts
    for k, phase in enumerate((0.0, 1.0)):
        np.testing.assert_allclose(rec.points[:, k], _circle(rec.t + start, phase), atol=1e-3)
    assert [label for label, _ in rec.events] == ["without", "with"]
    np.testing.assert_allclose([time for _, time in rec.events], [1.0 - start, 3.0 - start], atol=1e-9)


def test_labelled_channels_carry_several_markers_in_one_stream(tmp_path):
    t = np.arange(300) / 100.0
    table = np.hstack([_circle(t, 0.0), _circle(t, 2.0) / 10])
    labels = ["A_x", "A_y", "A_z", "B:X", "B:Y", "B:Z"]
    write_xdf(tmp_path / "one.xdf", [{"name": "mocap", "time_stamps": T0 + t, "time_series": table, "labels": labels}])
    with pytest.warns(UserWarning, match=r"one\.xdf: stream 'mocap' declares no unit: taken as mm"):
        rec = load_xdf_markers(tmp_path / "one.xdf", markers=["B", "A"])
    assert rec.markers == ("B", "A")
    np.testing.assert_allclose(rec.points[:, 1], _circle(rec.t, 0.0), atol=1e-6)
    rec_cm = load_xdf_markers(tmp_path / "one.xdf", unit="cm")  # the unit of channels that declare none
    np.testing.assert_allclose(rec_cm.points[:, 0], 10 * _circle(rec.t, 0.0), atol=1e-5)
    np.testing.assert_allclose(rec_cm.points[:, 1], _circle(rec.t, 2.0), atol=1e-5)  # B was written in cm


def test_errors_name_the_file_and_what_is_wrong(tmp_path):
    t = np.arange(100) / 100.0
    write_xdf(tmp_path / "deg.xdf", [{"name": "P1", "time_stamps": t, "time_series": _circle(t, 0), "unit": "deg"}])
    with pytest.raises(DataFormatError, match=r"deg\.xdf: stream 'P1': unit 'deg' is not a length unit"):
        load_xdf_markers(tmp_path / "deg.xdf")
    write_xdf(tmp_path / "p.xdf", [{"name": "P1", "time_stamps": t, "time_series": _circle(t, 0), "unit": "mm"}])
    with pytest.raises(DataFormatError, match=r"p\.xdf: no marker\(s\) 'P9' \(markers: P1\)"):
        load_xdf_markers(tmp_path / "p.xdf", markers=["P9"])
    write_xdf(tmp_path / "m.xdf", [{"name": "cond", "time_stamps": t[:2], "time_series": ["a", "b"]}])
    with pytest.raises(DataFormatError, match=r"m\.xdf: no marker stream"):
        load_xdf_markers(tmp_path / "m.xdf")
    (tmp_path / "bad.xdf").write_bytes(b"XDF:\x01\x07\x02\x00garbage")
    with pytest.raises(DataFormatError, match=r"bad\.xdf: not a readable XDF file"):
        load_xdf_markers(tmp_path / "bad.xdf")
    with pytest.raises(DataFormatError, match=r"p\.trc: expected a recording ending in \.c3d or \.xdf"):
        load_recording(tmp_path / "p.trc")
