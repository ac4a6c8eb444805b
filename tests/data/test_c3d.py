"""load_c3d on C3D files written by ezc3d: units, occlusions, rate and time, events, resampling, bad files."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("ezc3d")

from cogblocks.data.c3d import load_c3d, write_c3d  # noqa: E402
from cogblocks.data.loaders import DataFormatError  # noqa: E402

RATE = 120.0


def _trajectories(n: int = 360) -> tuple[np.ndarray, np.ndarray]:
    """Known positions in mm: a 0.5 Hz circle and a line, sampled at RATE."""
    t = np.arange(n) / RATE
    points = np.zeros((n, 2, 3))
    points[:, 0] = np.column_stack([300 * np.cos(np.pi * t), 300 * np.sin(np.pi * t), 1000 + 0 * t])
    points[:, 1] = np.column_stack([100 * t, -50 + 0 * t, 1500 + 20 * t])
    return t, points


@pytest.mark.parametrize(("unit", "per_mm"), [("m", 1e-3), ("cm", 0.1), ("mm", 1.0)])
def test_points_come_back_in_mm_whatever_the_files_unit(tmp_path, unit, per_mm):
    t, points = _trajectories()
    path = tmp_path / f"walk_{unit}.c3d"
    write_c3d(path, points * per_mm, ["hand", "head"], RATE, unit=unit)
    rec = load_c3d(path)
    assert rec.markers == ("hand", "head")
    assert rec.rate == RATE
    np.testing.assert_allclose(rec.t, t, atol=1e-12)
    # C3D stores float32: a relative error of ~1e-7 of the coordinates (a wrong factor would be 10x off)
    np.testing.assert_allclose(rec.points, points, rtol=3e-7, atol=1e-4)


def test_occluded_samples_are_nan_and_only_those(tmp_path):
    _, points = _trajectories()
    points[40:55, 0] = np.nan  # the hand occluded for 15 frames
    write_c3d(tmp_path / "occluded.c3d", points, ["hand", "head"], RATE)
    rec = load_c3d(tmp_path / "occluded.c3d")
    hidden = np.isnan(rec.points).any(axis=2)
    expected = np.zeros_like(hidden)
    expected[40:55, 0] = True
    np.testing.assert_array_equal(hidden, expected)
    np.testing.assert_array_equal(rec.gaps("hand"), expected[:, 0])


def test_markers_are_selected_in_the_order_asked_and_vicon_prefixes_match(tmp_path):
    _, points = _trajectories()
    write_c3d(tmp_path / "v.c3d", points, ["P1:hand", "P1:head"], RATE)
    rec = load_c3d(tmp_path / "v.c3d", markers=["head", "P1:hand"])
    assert rec.markers == ("P1:head", "P1:hand")
    np.testing.assert_allclose(rec.points[:, 0], points[:, 1], atol=1e-3)


def test_an_unknown_marker_is_refused_listing_the_markers_there(tmp_path):
    _, points = _trajectories()
    write_c3d(tmp_path / "m.c3d", points, ["hand", "head"], RATE)
    with pytest.raises(DataFormatError, match=r"m\.c3d: no marker 'wrist' \(markers: hand, head\)"):
        load_c3d(tmp_path / "m.c3d", markers=["wrist"])


def test_events_come_back_in_seconds_sorted_by_time(tmp_path):
    _, points = _trajectories()
    write_c3d(tmp_path / "e.c3d", points, ["hand", "head"], RATE, events=[("with_L2", 1.5), ("without_L2", 0.0)])
    rec = load_c3d(tmp_path / "e.c3d")
    assert [label for label, _ in rec.events] == ["without_L2", "with_L2"]
    np.testing.assert_allclose([time for _, time in rec.events], [0.0, 1.5], atol=1e-6)


def test_resampling_onto_the_tick_grid_follows_the_trajectory_and_keeps_gaps(tmp_path):
    t, points = _trajectories()
    points[100:112, 0] = np.nan
    write_c3d(tmp_path / "r.c3d", points, ["hand", "head"], RATE)
    rec = load_c3d(tmp_path / "r.c3d", resample=0.01)
    np.testing.assert_allclose(rec.t, 0.01 * np.arange(len(rec.t)), atol=1e-12)
    assert rec.rate == pytest.approx(100.0) and rec.t[-1] <= t[-1]
    truth = np.column_stack([300 * np.cos(np.pi * rec.t), 300 * np.sin(np.pi * rec.t)])
    seen = ~np.isnan(rec.points[:, 0, 0])
    # a cubic spline through 120 Hz samples of a 0.5 Hz circle of radius 300 mm: well under 0.01 mm
    assert np.max(np.abs(rec.points[seen, 0, :2] - truth[seen])) < 0.01
    # grid times strictly between the last sample before the gap and the first after it are NaN
    gap = (rec.t > t[99]) & (rec.t < t[112])
    np.testing.assert_array_equal(~seen, gap)


def test_a_unit_that_is_not_a_length_is_refused_naming_it(tmp_path):
    _, points = _trajectories()
    write_c3d(tmp_path / "deg.c3d", points, ["hand", "head"], RATE)
    import ezc3d

    c3d = ezc3d.c3d(str(tmp_path / "deg.c3d"))
    c3d["parameters"]["POINT"]["UNITS"]["value"] = ["deg"]
    c3d.write(str(tmp_path / "deg.c3d"))
    with pytest.raises(DataFormatError, match=r"deg\.c3d: POINT:UNITS: unit 'deg' is not a length unit"):
        load_c3d(tmp_path / "deg.c3d")


def test_a_truncated_file_is_refused_naming_it(tmp_path):
    _, points = _trajectories()
    write_c3d(tmp_path / "full.c3d", points, ["hand", "head"], RATE)
    data = (tmp_path / "full.c3d").read_bytes()
    (tmp_path / "cut.c3d").write_bytes(data[: len(data) // 2])
    with pytest.raises(DataFormatError, match=r"cut\.c3d: truncated: the header announces 360 frames"):
        load_c3d(tmp_path / "cut.c3d")
    (tmp_path / "stub.c3d").write_bytes(data[:300])
    with pytest.raises(DataFormatError, match=r"stub\.c3d: not a readable C3D file"):
        load_c3d(tmp_path / "stub.c3d")


def test_a_file_without_points_is_refused(tmp_path):
    import ezc3d

    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [100.0]
    c3d["data"]["points"] = np.ones((4, 0, 100))  # 100 frames of no marker
    c3d.write(str(tmp_path / "empty.c3d"))
    with pytest.raises(DataFormatError, match=r"empty\.c3d: the file holds no 3D points"):
        load_c3d(tmp_path / "empty.c3d")


def test_a_file_that_is_not_c3d_and_a_missing_file(tmp_path):
    (tmp_path / "notes.c3d").write_text("not a c3d file\n" * 100)
    with pytest.raises(DataFormatError, match=r"notes\.c3d: not a readable C3D file"):
        load_c3d(tmp_path / "notes.c3d")
    with pytest.raises(FileNotFoundError, match="missing.c3d"):
        load_c3d(tmp_path / "missing.c3d")
