"""LSLInlet and LSLOutlet on real LSL streams (loopback only, see conftest.py)."""

import inspect
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from cogblocks.sim import Diagram, DiagramError


def _outlet(lsl, name, channels=1, unit="mm", fmt=None):
    info = lsl.StreamInfo(name, "MoCap", channels, 100.0, fmt or lsl.cf_double64, f"{name}-src")
    chans = info.desc().append_child("channels")
    for _ in range(channels):
        chans.append_child("channel").append_child_value("unit", unit)
    return lsl.StreamOutlet(info)


def _inlets(name, **modes):
    from cogblocks.live import LSLInlet

    d = Diagram()
    blocks = {key: d.add(key, LSLInlet(name, timeout=2.0, **kw)) for key, kw in modes.items()}
    return d.compile(0.01), blocks


def test_every_live_block_states_its_bad_data_policy(lsl):
    from cogblocks.live import LSLInlet, LSLOutlet, OSCReceiver, OSCSender

    for cls in (LSLInlet, LSLOutlet, OSCReceiver, OSCSender):
        assert "Bad data policy" in inspect.getdoc(cls), cls.__name__


def test_the_core_package_and_the_command_line_load_no_live_dependency():
    code = (
        "import sys, cogblocks, cogblocks.sim, cogblocks.blocks, cogblocks.diagrams.sync, cogblocks.cli, "
        "cogblocks.live, cogblocks.live.cli, cogblocks.live.config, cogblocks.live.runner; "
        "print(sorted(m for m in sys.modules if m.split('.')[0] in ('pylsl', 'pythonosc')))"
    )
    root = Path(__file__).resolve().parents[2]
    out = subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_a_missing_stream_is_named_in_the_error(lsl, stream_name):
    from cogblocks.live import LSLInlet

    d = Diagram()
    d.add("arm", LSLInlet(f"{stream_name}-absent", stream_type="MoCap", timeout=0.3))
    with pytest.raises(
        TimeoutError,
        match=rf"arm: no LSL stream with name '{stream_name}-absent' and type 'MoCap' "
        r"found within 0.3 s",
    ):
        d.compile(0.01)


def test_channel_count_unit_and_format_are_checked_against_the_port(lsl, stream_name):
    keep = [
        _outlet(lsl, f"{stream_name}-two", channels=2),
        _outlet(lsl, f"{stream_name}-deg", unit="deg"),
        _outlet(lsl, f"{stream_name}-str", fmt=lsl.cf_string),
    ]
    with pytest.raises(DiagramError, match=r"has 2 channel\(s\), the port expects shape \(3,\) = 3 channel"):
        _inlets(f"{stream_name}-two", a={"shape": (3,), "unit": "mm"})
    with pytest.raises(
        DiagramError, match=r"-deg' \(type 'MoCap'\) declares unit 'deg', the port expects 'mm' or a length"
    ):
        _inlets(f"{stream_name}-deg", a={"unit": "mm"})
    with pytest.raises(DiagramError, match=r"declares unit 'deg', the port expects 'rad'$"):
        _inlets(f"{stream_name}-deg", a={"unit": "rad"})
    with pytest.raises(DiagramError, match="carries strings"):
        _inlets(f"{stream_name}-str", a={})
    # a (2, 1) port takes the two-channel stream
    compiled, blocks = _inlets(f"{stream_name}-two", a={"shape": (2, 1), "unit": "mm"})
    assert blocks["a"].y.value.shape == (2, 1)
    del keep


def _constant(lsl, outlet, value, stop):
    def run():
        while not stop.is_set():
            outlet.push_sample([value], lsl.local_clock())
            time.sleep(0.005)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread


def test_length_units_convert_and_a_stream_without_a_unit_is_named(lsl, stream_name):
    stop = threading.Event()
    outlets = {u: _outlet(lsl, f"{stream_name}-{u or 'none'}", unit=u) for u in ("m", "cm", "mm", "")}
    threads = [_constant(lsl, outlet, 1.25, stop) for outlet in outlets.values()]
    try:
        from cogblocks.live import LSLInlet

        d = Diagram()
        for u in ("m", "cm", "mm"):
            d.add(f"in_{u}", LSLInlet(f"{stream_name}-{u}", unit="mm", hold=1.0, timeout=2.0))
        d.add("given", LSLInlet(f"{stream_name}-none", unit="mm", source_unit="m", hold=1.0, timeout=2.0))
        d.add("to_m", LSLInlet(f"{stream_name}-cm", unit="m", hold=1.0, timeout=2.0))
        with pytest.warns(UserWarning) as caught:
            d.add("bare", LSLInlet(f"{stream_name}-none", unit="mm", hold=1.0, timeout=2.0))
            compiled = d.compile(0.01)
        (warning,) = caught
        assert str(warning.message) == (
            f"bare: LSL stream '{stream_name}-none' (type 'MoCap') declares no unit; its values are taken as 'mm' "
            "(give the stream's unit as source_unit, --unit on the command line)"
        )
        for _ in range(200):
            compiled.step()
            out = {name: d[name].y.value.item() for name in ("in_m", "in_cm", "in_mm", "given", "to_m", "bare")}
            if all(np.isfinite(v) for v in out.values()):
                break
            time.sleep(0.01)
        assert out == {"in_m": 1250.0, "in_cm": 12.5, "in_mm": 1.25, "given": 1250.0, "to_m": 0.0125, "bare": 1.25}
        d2 = Diagram()
        d2.add("a", LSLInlet(f"{stream_name}-m", unit="mm", source_unit="cm", timeout=2.0))
        with pytest.raises(DiagramError, match=r"declares unit\(s\) \['m'\]; source_unit 'cm' is for a stream"):
            d2.compile(0.01)
    finally:
        stop.set()
        for thread in threads:
            thread.join()


def _expected(at, stamps, values, hold):
    """Linear interpolation of the pushed samples at time ``at``; NaN across a gap or a missing sample."""
    stamps, values = np.asarray(stamps), np.asarray(values)
    if at >= stamps[-1]:
        return values[-1] if at - stamps[-1] <= hold else np.nan
    i = np.searchsorted(stamps, at, side="right") - 1
    if i < 0 or stamps[i + 1] - stamps[i] > hold:
        return np.nan
    w = (at - stamps[i]) / (stamps[i + 1] - stamps[i])
    return (1 - w) * values[i] + w * values[i + 1]


def _push_in_time(lsl, outlet, stamps, values):
    """Push each sample when the LSL clock reaches its stamp, as a tracker would."""

    def run():
        for stamp, value in zip(stamps, values, strict=True):
            while lsl.local_clock() < stamp:
                time.sleep(0.0005)
            outlet.push_sample([value], stamp)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread


def test_irregular_samples_become_one_value_per_tick(lsl, stream_name):
    outlet = _outlet(lsl, stream_name)
    compiled, blocks = _inlets(
        stream_name, latest={"unit": "mm"}, interp={"unit": "mm", "mode": "interpolate", "lag": 0.03, "hold": 0.05}
    )
    # samples 10 ms apart with jitter, a missing sample (NaN, and an inf that counts as missing) and an
    # 150 ms gap; the ticks, about every 10 ms, read them as they come
    t0 = lsl.local_clock() + 0.1
    jitter = np.random.default_rng(0).uniform(-0.003, 0.003, 60)
    stamps = [t0 + 0.01 * j + jitter[j] for j in range(60) if not 20 <= j < 35]
    values = [float(10 * j) for j in range(60) if not 20 <= j < 35]
    values[8], values[12] = np.nan, np.inf
    pusher = _push_in_time(lsl, outlet, stamps, values)
    values[12] = np.nan
    seen = {"interp": 0, "interp_nan": 0, "stale": 0, "fresh": 0}
    grid = []
    next_tick = time.perf_counter()
    while lsl.local_clock() < stamps[-1] + 0.1:
        compiled.step()
        for key, inlet in blocks.items():
            n = inlet.samples_in  # they arrive in order: the first n were received
            if n == 0:
                assert np.isnan(inlet.y.value) and inlet.age_ms.value == np.inf
                continue
            got = inlet.y.value.item()
            assert inlet.age_ms.value == pytest.approx(1e3 * (inlet.tick_time - inlet.sample_time))
            if key == "latest":
                assert abs(inlet.sample_time - stamps[n - 1]) < 1e-4  # the newest sample received
                expected = values[n - 1] if inlet.tick_time - stamps[n - 1] <= 0.05 else np.nan
                seen["stale"] += np.isnan(got)
                seen["fresh"] += bool(inlet.fresh.value)
            else:
                grid.append(inlet.sample_time)
                expected = _expected(inlet.sample_time, stamps[:n], values[:n], 0.05)
                seen["interp"] += np.isfinite(got)
                seen["interp_nan"] += np.isnan(got)
            # LSL's clock offset between inlet and outlet is measured, to some 10 µs: 1 % of a step here
            np.testing.assert_allclose(got, expected, atol=0.1, err_msg=key)
        next_tick += 0.01
        time.sleep(max(0.0, next_tick - time.perf_counter()))
    # the interpolating inlet read the stream on the grid of the ticks, whenever they ran
    np.testing.assert_allclose(np.diff(grid), 0.01, atol=1e-9)
    pusher.join()
    assert seen["interp"] > 10 and seen["interp_nan"] > 2 and seen["stale"] > 2 and seen["fresh"] > 10
    compiled.step()
    assert not bool(blocks["latest"].fresh.value) and np.isnan(blocks["latest"].y.value)


def test_a_slow_first_pull_does_not_shift_the_interpolation_grid(lsl, stream_name, monkeypatch):
    from cogblocks.live import LSLInlet

    outlet = _outlet(lsl, stream_name)
    compiled, blocks = _inlets(stream_name, a={"unit": "mm", "mode": "interpolate", "lag": 0.02})
    inlet = blocks["a"]
    receive = LSLInlet._receive
    calls = []

    def slow_first(self):
        if not calls:
            time.sleep(0.02)  # a busy machine holds up the first pull
        calls.append(1)
        return receive(self)

    monkeypatch.setattr(LSLInlet, "_receive", slow_first)
    before = lsl.local_clock()
    compiled.step()
    # the grid starts when the tick did, not when its pull came back: the value is lag before the tick's start
    assert 0.0 <= inlet.sample_time + 0.02 - before < 0.01
    assert inlet.age_ms.value >= 40.0
    del outlet


def test_a_stream_that_stops_gives_nan_and_an_ageing_sample(lsl, stream_name):
    outlet = _outlet(lsl, stream_name, channels=2)
    # hold long enough that a loaded machine still steps within it, short enough to wait out
    compiled, blocks = _inlets(stream_name, a={"shape": (2,), "unit": "mm", "hold": 0.5})
    inlet = blocks["a"]
    compiled.step()
    assert np.all(np.isnan(inlet.y.value)) and inlet.age_ms.value == np.inf and not inlet.fresh.value
    outlet.push_sample([1.5, -2.5], lsl.local_clock())
    deadline = time.monotonic() + 2.0
    while inlet.samples_in == 0 and time.monotonic() < deadline:
        compiled.step()
    assert inlet.fresh.value and inlet.y.value.tolist() == [1.5, -2.5]
    time.sleep(0.6)
    compiled.step()
    assert not inlet.fresh.value and np.all(np.isnan(inlet.y.value)) and inlet.age_ms.value > 600.0


def test_wrapped_angles_are_interpolated_along_the_shorter_arc(lsl, stream_name):
    outlet = _outlet(lsl, stream_name, unit="rad")
    compiled, blocks = _inlets(
        stream_name, a={"unit": "rad", "wrapped": True, "mode": "interpolate", "lag": 0.0, "hold": 10.0}
    )
    t0 = lsl.local_clock() + 0.2
    outlet.push_sample([2 * np.pi - 0.1], t0)
    outlet.push_sample([0.1], t0 + 1.0)
    while lsl.local_clock() < t0 + 0.3:
        time.sleep(0.01)
    compiled.step()
    frac = blocks["a"].sample_time - t0  # the first tick starts the grid: lag 0 reads the stream at the tick
    expected = np.mod(2 * np.pi - 0.1 + 0.2 * frac, 2 * np.pi)  # through 0, not back across π
    assert blocks["a"].y.value.item() == pytest.approx(expected, abs=1e-3)


def test_outlet_publishes_every_tick_with_its_metadata(lsl, stream_name):
    from cogblocks.blocks import Playback
    from cogblocks.live import LSLOutlet

    d = Diagram()
    src = d.add("src", Playback(np.tile([[1.0, np.nan], [3.0, -4.25]], (5, 1, 1)), unit="mm"))
    out = d.add("out", LSLOutlet(stream_name, stream_type="MoCap", channel_names=["a", "b", "c", "d"]))
    d.connect(src.y, out.u)
    compiled = d.compile(0.01)
    found = lsl.resolve_byprop("name", stream_name, timeout=2.0)
    assert len(found) == 1
    inlet = lsl.StreamInlet(found[0])
    info = inlet.info(2.0)
    assert (info.type(), info.channel_count(), info.nominal_srate(), info.source_id()) == (
        "MoCap",
        4,
        100.0,
        f"cogblocks-{stream_name}",
    )
    chan = info.desc().child("channels").child("channel")
    labels_units = []
    while not chan.empty():
        labels_units.append((chan.child_value("label"), chan.child_value("unit")))
        chan = chan.next_sibling("channel")
    assert labels_units == [("a", "mm"), ("b", "mm"), ("c", "mm"), ("d", "mm")]
    assert info.desc().child("cogblocks").child_value("shape") == "2,2"
    inlet.open_stream(2.0)
    pushed = []
    for _ in range(5):
        compiled.step()
        pushed.append(out.last_timestamp)
    samples, stamps = [], []
    deadline = time.monotonic() + 2.0
    while len(samples) < 5 and time.monotonic() < deadline:
        chunk, ts = inlet.pull_chunk(timeout=0.1)
        samples += chunk
        stamps += ts
    assert out.samples_out == 5
    np.testing.assert_array_equal(np.array(samples), np.tile([1.0, np.nan, 3.0, -4.25], (5, 1)))
    np.testing.assert_allclose(stamps, pushed, atol=1e-6)
