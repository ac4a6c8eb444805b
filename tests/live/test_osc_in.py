"""OSCReceiver on the loopback interface: latest, hold and NaN as LSLInlet, units, a recorded OSC session replayed."""

import threading
import time

import numpy as np
import pytest

pytest.importorskip("pythonosc", reason="python-osc (the live extra) is not installed")

from pythonosc.udp_client import SimpleUDPClient  # noqa: E402

from cogblocks.sim import Diagram, DiagramError  # noqa: E402


def _receiver(**kw):
    from cogblocks.live import OSCReceiver

    d = Diagram()
    block = d.add("osc", OSCReceiver("/arm/p", **kw))
    return d.compile(0.01), block


def _wait_for(block, compiled, n):
    for _ in range(500):
        compiled.step()
        if block.samples_in >= n:
            return
        time.sleep(0.002)
    raise AssertionError(f"{block.samples_in} of {n} OSC messages arrived")


def test_latest_holds_then_gives_nan_and_bad_messages_are_nan(recwarn):
    compiled, block = _receiver(shape=(2,), unit="mm", source_unit="m", hold=0.2)
    try:
        client = SimpleUDPClient("127.0.0.1", block.port)
        assert block.port > 0
        client.send_message("/other", [9.0, 9.0])  # another address: ignored
        client.send_message("/arm/p", [0.5, -0.25])
        _wait_for(block, compiled, 1)
        np.testing.assert_array_equal(block.y.value, [500.0, -250.0])  # metres in, mm out
        assert bool(block.fresh.value) and 0.0 <= block.age_ms.value < 200.0
        compiled.step()
        assert not bool(block.fresh.value) and np.array_equal(block.y.value, [500.0, -250.0])  # held
        client.send_message("/arm/p", [1.0])  # one value for two channels
        client.send_message("/arm/p", ["x", 2.0])
        _wait_for(block, compiled, 3)
        assert block.rejected == 2 and np.all(np.isnan(block.y.value))
        client.send_message("/arm/p", [float("inf"), 0.125])  # OSC floats are 32-bit: exact ones
        _wait_for(block, compiled, 4)
        assert np.isnan(block.y.value[0]) and block.y.value[1] == 125.0
        time.sleep(0.25)  # longer than hold
        compiled.step()
        assert np.all(np.isnan(block.y.value)) and block.age_ms.value > 200.0
        assert block.samples_in == 4 and not recwarn.list  # source_unit given: no warning
    finally:
        block.close()


def test_interpolation_reads_the_stream_lag_back_on_the_tick_grid():
    compiled, block = _receiver(unit="mm", source_unit="mm", mode="interpolate", lag=0.03, hold=0.05, record=True)
    client = SimpleUDPClient("127.0.0.1", block.port)
    stop = threading.Event()

    def send():
        k = 0
        while not stop.is_set():
            client.send_message("/arm/p", [float(k)])
            k += 1
            time.sleep(0.01)

    sender = threading.Thread(target=send, daemon=True)
    sender.start()
    got, at, counts = [], [], []
    try:
        for _ in range(60):
            compiled.step()
            got.append(block.y.value.item())
            at.append(block.sample_time)
            counts.append(block.samples_in)
            time.sleep(0.01)
    finally:
        stop.set()
        sender.join()
        block.close()
    t, x = block.raw()
    assert x.shape == t.shape  # a scalar port: one value per sample
    checked = 0
    for value, when, n in zip(got, at, counts, strict=True):
        ts, xs = t[:n], x[:n]
        if n == 0 or when < ts[0]:
            assert np.isnan(value)
            continue
        i = int(np.searchsorted(ts, when, side="right")) - 1
        if i == len(ts) - 1:
            expected = xs[-1] if when - ts[-1] <= 0.05 else np.nan
        elif ts[i + 1] - ts[i] > 0.05:
            expected = np.nan
        else:
            expected = xs[i] + (when - ts[i]) / (ts[i + 1] - ts[i]) * (xs[i + 1] - xs[i])
        np.testing.assert_allclose(value, expected, rtol=0, atol=1e-9)
        checked += np.isfinite(value)
    assert checked > 30
    np.testing.assert_allclose(np.diff(at), 0.01, atol=1e-9)  # on the grid, whenever the ticks ran


def test_a_stream_without_a_unit_is_taken_in_the_port_unit_with_a_warning():
    with pytest.warns(UserWarning, match=r"osc: OSC address '/arm/p' \(type 'OSC'\) declares no unit; .* as 'mm'"):
        compiled, block = _receiver(unit="mm")
    block.close()
    with pytest.raises(DiagramError, match=r"declares unit 'deg', the port expects 'mm' or a length"):
        _receiver(unit="mm", source_unit="deg")


def test_a_recorded_osc_session_replays_bit_for_bit(tmp_path):
    from cogblocks.live import OSCReceiver, load_session, replay_session, run_realtime, write_session
    from cogblocks.live.session import enable_recording
    from cogblocks.phase import PhaseEstimator

    def build():
        d = Diagram()
        osc = d.add("osc", OSCReceiver("/arm/p", unit="mm", source_unit="cm", mode="interpolate", lag=0.02))
        est = d.add("phase", PhaseEstimator(unit="mm"))
        d.connect(osc.y, est.p)
        d.expose_output("theta", est.theta)
        d.expose_output("sample", osc.y)
        return d

    compiled = build().compile(0.01)
    enable_recording(compiled)
    osc = compiled.blocks["osc"]
    client, stop = SimpleUDPClient("127.0.0.1", osc.port), threading.Event()

    def send():
        start = time.monotonic()
        while not stop.is_set():
            client.send_message("/arm/p", [15.0 * np.cos(2 * np.pi * (time.monotonic() - start))])
            time.sleep(0.01)

    sender = threading.Thread(target=send, daemon=True)
    sender.start()
    try:
        report = run_realtime(compiled, 1.5, record=True)
    finally:
        stop.set()
        sender.join()
        osc.close()
    path = write_session(tmp_path / "osc.xdf", compiled, report)
    again = replay_session(build(), load_session(path))
    assert report.samples_in > 100 and again.samples_in == report.samples_in
    for name in ("theta", "sample"):
        np.testing.assert_array_equal(again.trace[name], report.trace[name], err_msg=name)
    assert np.nanmax(report.trace["sample"]) > 100.0  # cm in, mm out
