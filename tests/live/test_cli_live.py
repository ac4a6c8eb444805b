"""``cogblocks live``: ready diagrams on real LSL streams, JSON figures, Ctrl-C with the trace saved."""

import json
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]


def _cli(*args):
    return subprocess.Popen(
        [sys.executable, "-X", "faulthandler", "-m", "cogblocks.cli", "live", *args],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _reader(lsl, name):
    found = lsl.resolve_byprop("name", name, timeout=20.0)
    assert found, f"cogblocks live did not publish {name!r}"
    reader = lsl.StreamInlet(found[0], max_buflen=60)
    reader.open_stream(5.0)
    return reader


def test_l1_live_prints_its_figures_as_json(lsl, streamer, stream_name, capsys):
    from cogblocks.cli import main

    marker = streamer(f"{stream_name}-marker", lambda t: 100.0 * np.sin(2 * np.pi * np.array([0.5, 0.7, 0.9]) * t), 3)
    received = []
    reader = threading.Thread(target=lambda: received.append(_read_all(lsl, f"{stream_name}-avatar")), daemon=True)
    reader.start()
    code = main(
        ["live", "l1", "--in", f"{stream_name}-marker", "--out", f"{stream_name}-avatar", "--duration", "1.5", "--json"]
    )
    reader.join(timeout=10.0)
    assert code == 0
    result = json.loads(capsys.readouterr().out)
    assert set(result) == {
        "ticks",
        "late_ticks",
        "tick_ms_p50",
        "tick_ms_p99",
        "samples_in",
        "samples_out",
        "max_age_ms",
    }
    assert result["ticks"] == result["samples_out"] == 150
    # the marker streamed about 150 samples during the run, and those buffered since the inlet opened
    # the inlet reads the stream 100 ms (--delay) + 20 ms back: that is the age of what it gives
    assert 140 <= result["samples_in"] <= 400 and 120.0 <= result["max_age_ms"] < 250.0
    assert 0.0 < result["tick_ms_p50"] <= result["tick_ms_p99"]
    ((info, samples),) = received
    assert (info.type(), info.nominal_srate(), info.channel_count()) == ("MoCap", 100.0, 3)
    assert samples.shape[1] == 3 and len(samples) > 50
    del marker


def _read_all(lsl, name):
    """Read the stream ``name`` until it goes away; its info and samples."""
    reader = _reader(lsl, name)
    samples = []
    while True:
        try:
            chunk, _ = reader.pull_chunk(timeout=0.3)
        except lsl.util.LostError:
            break
        if not chunk and samples:
            break
        samples += chunk
    return reader.info(), np.array(samples)


def test_ctrl_c_stops_the_run_and_saves_the_trace(lsl, streamer, stream_name, tmp_path):
    streamer(f"{stream_name}-arm", lambda t: 150.0 * np.cos(2 * np.pi * t))
    saved = tmp_path / "run.npz"
    cli = _cli(
        "phase", "--in", f"{stream_name}-arm", "--out", f"{stream_name}-phase", "--duration", "60", "--save", str(saved)
    )
    reader = _reader(lsl, f"{stream_name}-phase")
    reader.pull_sample(timeout=5.0)  # it runs
    time.sleep(0.5)
    cli.send_signal(signal.SIGINT)
    try:
        out, err = cli.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        cli.send_signal(signal.SIGABRT)  # -X faulthandler: the process prints every thread's stack, then dies
        _, err = cli.communicate(timeout=10)
        pytest.fail(f"cogblocks live did not stop within 30 s of Ctrl-C; where its threads were:\n{err[-6000:]}")
    assert cli.returncode == 0, err
    assert "(stopped by Ctrl-C)" in out and f"saved the trace and the raw samples to {saved}" in out
    with np.load(saved) as run:
        summary = json.loads(str(run["summary"]))
        assert summary["interrupted"] and 10 < summary["ticks"] < 6000
        assert len(run["t"]) == len(run["theta"]) == len(run["tick_ms"]) == summary["ticks"]
        assert len(run["raw/inlet/t"]) == len(run["raw/inlet/x"]) == summary["samples_in"] > 0
        np.testing.assert_allclose(run["raw/inlet/x"], 150.0 * np.cos(2 * np.pi * run["raw/inlet/t"]), atol=0.05)


def test_a_missing_input_stream_is_a_clear_error(lsl, stream_name, capsys):
    from cogblocks.cli import main

    code = main(
        [
            "live",
            "sync",
            "--in",
            f"{stream_name}-nobody",
            "--out",
            "x",
            "--duration",
            "1",
            "--timeout",
            "0.3",
            "--policy",
            "mean",
        ]
    )
    captured = capsys.readouterr()
    assert code == 2 and captured.out == ""
    assert f"cogblocks: error: inlet: no LSL stream with name '{stream_name}-nobody' found within 0.3 s" in captured.err


def test_a_recorded_l1_session_replays_to_the_same_trace_and_json_keys(lsl, streamer, stream_name, tmp_path, capsys):
    from cogblocks.cli import main

    streamer(f"{stream_name}-m", lambda t: 0.1 * np.sin(2 * np.pi * np.array([0.5, 0.7, 0.9]) * t), 3, unit="m")
    record, live_npz, replay_npz = tmp_path / "s.xdf", tmp_path / "live.npz", tmp_path / "replay.npz"
    args = ["--in", f"{stream_name}-m", "--out", f"{stream_name}-av", "--duration", "1.5", "--delay", "0.05"]
    code = main(["live", "l1", *args, "--record", str(record), "--save", str(live_npz), "--json"])
    live = json.loads(capsys.readouterr().out)
    assert code == 0 and record.is_file()
    # the recorded options (streams, delay) are the defaults of the replay
    code = main(["replay", str(record), "l1", "--save", str(replay_npz), "--json"])
    replayed = json.loads(capsys.readouterr().out)
    assert code == 0 and set(replayed) == set(live)
    assert replayed["ticks"] == live["ticks"] == 150 and replayed["samples_in"] == live["samples_in"]
    assert (replayed["late_ticks"], replayed["max_age_ms"]) == (live["late_ticks"], live["max_age_ms"])
    with np.load(live_npz) as a, np.load(replay_npz) as b:
        for name in ("t", "p_avatar", "sample", "age_ms", "fresh"):
            np.testing.assert_array_equal(b[name], a[name], err_msg=name)
        assert np.nanmax(np.abs(a["sample"])) > 50.0  # mm, converted from the stream's metres
    # another delay replays the same samples through another diagram
    assert main(["replay", str(record), "l1", "--delay", "0.02", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["ticks"] == 150


def test_the_record_path_is_checked_before_the_run(lsl, stream_name, tmp_path, capsys):
    from cogblocks.cli import main

    bad = tmp_path / "missing" / "s.xdf"
    code = main(["live", "phase", "--in", f"{stream_name}-x", "--out", "o", "--duration", "60", "--record", str(bad)])
    captured = capsys.readouterr()
    assert code == 2
    assert "argument --record" in captured.err and "no folder" in captured.err and str(bad.parent) in captured.err
    code = main(["live", "phase", "--in", "x", "--out", "o", "--duration", "1", "--record", str(tmp_path / "s.csv")])
    assert code == 2 and "ending in one of .xdf" in capsys.readouterr().err


def test_view_serves_a_saved_trace_until_ctrl_c(tmp_path, view_server):
    t = 0.01 * np.arange(500)
    np.savez(tmp_path / "run.npz", t=t, theta=np.mod(t, 2 * np.pi), tick_ms=np.ones(500), start_ms=np.zeros(500))
    view = view_server(tmp_path / "run.npz")
    assert view.line.startswith(f"view of {tmp_path / 'run.npz'} at http://127.0.0.1:"), view.line
    meta, data = view.get("meta"), view.get("data")
    assert meta["mode"] == "view" and [p["series"] for p in meta["panels"]] == [["theta"], ["late"]]
    assert data["t"] == t.tolist() and data["ticks"] == 500 and data["theta"][7] == [0.07]
    code, err = view.stop()
    assert code == 0, err


def test_live_scope_serves_the_run_on_loopback(lsl, streamer, stream_name):
    import urllib.request

    streamer(f"{stream_name}-arm", lambda t: 150.0 * np.cos(2 * np.pi * t))
    cli = _cli("phase", "--in", f"{stream_name}-arm", "--out", f"{stream_name}-ph", "--duration", "4", "--scope", "0")
    try:
        line = ""
        while not line.startswith("scope at ") and cli.poll() is None:
            line = cli.stderr.readline()  # after liblsl's own messages, if any
        assert line.startswith("scope at http://127.0.0.1:"), line
        url = line.split(" at ")[1].strip()
        meta = json.loads(urllib.request.urlopen(url + "meta", timeout=10).read())
        assert meta["mode"] == "live" and meta["title"] == "cogblocks live phase"
        assert [p["series"] for p in meta["panels"]] == [["sample"], ["theta"], ["late"]]
        with urllib.request.urlopen(url + "events", timeout=10) as events:
            first = next(line for line in events if line.startswith(b"data: "))
        rows = json.loads(first[len(b"data: ") :])
        assert rows["ticks"] > 0 and len(rows["t"]) == len(rows["theta"]) == len(rows["sample"]) > 0
    finally:
        out, err = cli.communicate(timeout=60)
    assert cli.returncode == 0, err
    assert "400 ticks at 100 Hz" in out


def _recorded_ticks(pyxdf, path):
    """Ticks of the run stream in the session file as it is now (0 before the first write)."""
    if not path.exists():
        return 0
    streams, _ = pyxdf.load_xdf(str(path), synchronize_clocks=False, dejitter_timestamps=False)
    return sum(len(s["time_stamps"]) for s in streams if s["info"]["name"][0] == "cogblocks run")


def test_a_run_killed_mid_session_leaves_a_file_that_replays_tick_for_tick(lsl, streamer, stream_name, tmp_path):
    """The session is written as the run goes: after SIGKILL the file reads and replays what was computed."""
    pyxdf = pytest.importorskip("pyxdf", reason="the recordings extra (pyxdf) is not installed")
    from cogblocks.cli import main

    streamer(f"{stream_name}-arm", lambda t: 150.0 * np.cos(2 * np.pi * t))
    record, replayed = tmp_path / "s.xdf", tmp_path / "replay.npz"
    arm, out = f"{stream_name}-arm", f"{stream_name}-phase"
    cli = _cli("phase", "--in", arm, "--out", out, "--duration", "600", "--record", str(record))
    try:
        _reader(lsl, out).pull_sample(timeout=5.0)  # it runs
        deadline = time.monotonic() + 120  # a guard against a hung run, not a measure of speed
        while _recorded_ticks(pyxdf, record) < 100:
            assert time.monotonic() < deadline and cli.poll() is None, "no ticks written to the session file"
            time.sleep(0.2)
    finally:
        cli.kill()
        cli.communicate(timeout=30)
    assert cli.returncode == -signal.SIGKILL
    streams, _ = pyxdf.load_xdf(str(record), synchronize_clocks=False, dejitter_timestamps=False)
    by_name = {s["info"]["name"][0]: s for s in streams}
    assert set(by_name) == {arm, out, "inlet ticks", "cogblocks run"}
    n = len(by_name["cogblocks run"]["time_stamps"])
    assert n >= 100 and len(by_name["inlet ticks"]["time_stamps"]) >= n and len(by_name[arm]["time_stamps"]) > 0
    # the replay computes, tick for tick, the phase the killed run published
    assert main(["replay", str(record), "phase", "--save", str(replayed), "--json"]) == 0
    with np.load(replayed) as run:
        assert len(run["theta"]) == n
        np.testing.assert_array_equal(run["theta"], by_name[out]["time_series"][:n, 0])
