"""The 3D phase chain and L1 on recorded C3D markers (synthesised with a known phase, written with ezc3d)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("ezc3d")

from cogblocks.blocks import Playback, Probe  # noqa: E402
from cogblocks.blocks.angles import wrap_pi  # noqa: E402
from cogblocks.data.c3d import load_c3d, write_c3d  # noqa: E402
from cogblocks.data.motion3d import generate_motion3d  # noqa: E402
from cogblocks.diagrams.phase3d import run_phase_estimator  # noqa: E402
from cogblocks.diagrams.recording import phase3d_recording, recorded_motion  # noqa: E402
from cogblocks.sensing import L1  # noqa: E402
from cogblocks.sim import Diagram, Simulator  # noqa: E402


@pytest.fixture(scope="module")
def motion():
    return generate_motion3d(4, duration=20.0)


def _write(path, motion, unit="mm", per_mm=1.0):
    p = motion.position.copy()
    p[motion.dropout] = np.nan  # the tracker lost the marker: occluded in the file
    write_c3d(path, p[:, None] * per_mm, ["LWRA", "RWRA"][:1], 1 / motion.dt, unit=unit)
    return path


def test_the_online_phase_of_a_recorded_marker_follows_the_true_phase(tmp_path, motion):
    rec_motion = recorded_motion(_write(tmp_path / "arm.c3d", motion), "LWRA")
    assert rec_motion.reference.shape == (200, 3)
    run = run_phase_estimator(rec_motion)
    valid = run["valid"] & ~motion.dropout
    error = np.abs(wrap_pi(run["theta"][valid] - motion.phase[valid]))
    assert valid.mean() > 0.8
    assert error.mean() < 0.15  # the reference is the recording's own mean cycle, not the primitive


def test_phase3d_on_a_recording_gives_the_same_figures_in_metres_and_millimetres(tmp_path, motion):
    in_mm = phase3d_recording(_write(tmp_path / "mm.c3d", motion), "LWRA")
    in_m = phase3d_recording(_write(tmp_path / "m.c3d", motion, "m", 1e-3), "LWRA")
    assert in_mm["mean_error_vs_offline_rad"] < 0.1 and in_mm["gap_share"] == pytest.approx(motion.dropout.mean())
    for key in ("mean_error_vs_offline_rad", "p95_error_vs_offline_rad", "valid_share"):
        assert in_m[key] == pytest.approx(in_mm[key], abs=1e-3)
    assert in_m["chain"]["r_mean"] == pytest.approx(in_mm["chain"]["r_mean"], abs=1e-3)
    assert 0.0 <= in_mm["chain"]["r_mean"] <= 1.0 and in_mm["chain"]["valid_from_s"] > 1.0


def test_l1_takes_a_recorded_marker_and_holds_through_its_gaps(tmp_path, motion):
    rec = load_c3d(_write(tmp_path / "arm.c3d", motion), ["LWRA"], resample=0.01)
    d = Diagram()
    d.add("recording", Playback(rec.marker("LWRA"), unit="mm"))
    d.add("l1", L1(delay=0.05))
    d.connect("recording.y", "l1.p")
    d.add("avatar", Probe())
    d.connect("l1.p_avatar", "avatar.u")
    trace = Simulator(d, dt=0.01).run(n_steps=len(rec.t))
    shown = trace["avatar"]
    assert np.isfinite(shown[1:]).all()  # through every gap of the recording
    # delay 50 ms: the avatar shows where the marker will be 5 ticks later
    ahead = rec.marker("LWRA")[5:]
    seen = ~np.isnan(ahead).any(axis=1)
    error = np.linalg.norm(shown[:-5][seen] - ahead[seen], axis=1)
    lag = np.linalg.norm(rec.marker("LWRA")[:-5][seen] - ahead[seen], axis=1)  # where it is now: ~25 mm behind
    assert np.median(error) < 8.0 and np.median(error) < 0.3 * np.nanmedian(lag)
