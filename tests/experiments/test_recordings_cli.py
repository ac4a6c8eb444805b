"""``cogblocks analyse group`` and ``cogblocks run phase3d --recording`` on files the test writes."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("ezc3d")
pytest.importorskip("pyxdf")

from cogblocks.cli import main  # noqa: E402
from cogblocks.data.c3d import write_c3d  # noqa: E402
from cogblocks.data.group_session import group_recording  # noqa: E402
from cogblocks.data.motion3d import generate_motion3d  # noqa: E402
from cogblocks.data.xdf import write_xdf  # noqa: E402


@pytest.fixture(scope="module")
def session():
    """Four people locked for 20 s, then moving each at their own tempo for 20 s; conditions marked."""
    rng = np.random.default_rng(5)
    t = 0.01 * np.arange(4000)
    locked = np.pi * t + rng.normal(0, 0.2, (4, 1))
    own = 2 * np.pi * rng.uniform(0.4, 0.6, (4, 1)) * t + rng.uniform(0, 2 * np.pi, (4, 1))
    theta = np.where(t < 20.0, locked, own) + np.cumsum(rng.normal(0, 0.01, (4, len(t))), axis=1)
    return group_recording(theta, names=["A", "B", "C", "D"], seed=5, events=[("with_L2", 0.0), ("without_L2", 20.0)])


def test_analyse_group_on_c3d_and_xdf_gives_the_same_answer(tmp_path, capsys, session):
    write_c3d(tmp_path / "s.c3d", session.points / 1000, session.markers, 100, unit="m", events=session.events)
    streams = [
        {"name": name, "time_stamps": 700 + session.t, "time_series": session.points[:, k], "unit": "mm",
         "labels": ["x", "y", "z"]}
        for k, name in enumerate(session.markers)
    ]  # fmt: skip
    streams.append(
        {"name": "cond", "time_stamps": 700 + np.array([0.0, 20.0]), "time_series": ["with_L2", "without_L2"]}
    )
    write_xdf(tmp_path / "s.xdf", streams)
    results = []
    for name in ("s.c3d", "s.xdf"):
        args = ["analyse", "group", str(tmp_path / name), "--markers", "A,B,C,D", "--offline-only", "--json"]
        assert main(args) == 0
        results.append(json.loads(capsys.readouterr().out))
    c3d, xdf = results
    assert c3d["offline"]["r_mean"] == pytest.approx(xdf["offline"]["r_mean"], abs=1e-4)
    for result in results:
        assert set(result["conditions"]) == {"with_L2", "without_L2"}
        assert result["conditions"]["with_L2"]["offline"]["above_chance"]
        assert not result["conditions"]["without_L2"]["offline"]["above_chance"]
        assert result["online"] is None and "series" not in result and "null" not in result["offline"]


def test_analyse_group_prints_text_and_draws_its_plot(tmp_path, capsys, session):
    short = group_recording(np.angle(np.exp(1j * np.pi * session.t[:1500]))[None].repeat(3, 0), seed=1)
    write_c3d(tmp_path / "g.c3d", short.points, short.markers, 100)
    assert (
        main(["analyse", "group", str(tmp_path / "g.c3d"), "--markers", "P1,P2,P3", "--plot", str(tmp_path / "g.png")])
        == 0
    )
    out = capsys.readouterr()
    assert "time-averaged r" in out.out and "online vs offline" in out.out
    assert (tmp_path / "g.png").stat().st_size > 0 and "wrote" in out.err


def test_bad_analyse_requests_are_refused_before_any_work(tmp_path, capsys, session):
    write_c3d(tmp_path / "g.c3d", session.points[:500], session.markers, 100)
    assert main(["analyse", "group", str(tmp_path / "g.c3d"), "--markers", "A"]) == 2
    assert "at least 2 distinct marker names" in capsys.readouterr().err
    assert main(["analyse", "group", str(tmp_path / "g.c3d"), "--markers", "A,Z"]) == 2
    assert "no marker 'Z' (markers: A, B, C, D)" in capsys.readouterr().err
    assert (
        main(["analyse", "group", str(tmp_path / "g.c3d"), "--markers", "A,B", "--plot", str(tmp_path / "no/x.png")])
        == 2
    )
    assert "no folder" in capsys.readouterr().err


def test_run_phase3d_on_a_recording(tmp_path, capsys):
    motion = generate_motion3d(2, duration=15.0)
    write_c3d(tmp_path / "arm.c3d", motion.position[:, None] / 10, ["RWRA"], 100, unit="cm")
    figure = tmp_path / "arm.png"
    args = [
        "run",
        "phase3d",
        "--recording",
        str(tmp_path / "arm.c3d"),
        "--marker",
        "RWRA",
        "--json",
        "--plot",
        str(figure),
    ]
    assert main(args) == 0
    assert figure.stat().st_size > 0
    result = json.loads(capsys.readouterr().out)
    assert result["marker"] == "RWRA" and result["mean_error_vs_offline_rad"] < 0.1
    assert {"r_mean", "valid_from_s", "mean_dev_rad", "max_dev_rad", "avatar_path_mm"} <= set(result["chain"])
    assert main(["run", "phase3d", "--recording", str(tmp_path / "arm.c3d")]) == 2
    assert "--recording needs --marker NAME" in capsys.readouterr().err
    assert main(["run", "phase3d", "--marker", "RWRA"]) == 2
    assert "give --recording too" in capsys.readouterr().err
    assert main(["run", "phase3d", "--recording", str(tmp_path / "arm.c3d"), "--marker", "RWRA", "--seed", "3"]) == 2
    assert "drop --trajectories, --seed, --rate and --set" in capsys.readouterr().err
