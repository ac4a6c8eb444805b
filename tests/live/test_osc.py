"""OSCSender against python-osc's own UDP server on 127.0.0.1."""

import threading
import time

import numpy as np
import pytest

from cogblocks.sim import Diagram


@pytest.fixture
def osc_server():
    """A python-osc server on an ephemeral loopback port; yields (port, received messages)."""
    dispatch = pytest.importorskip("pythonosc.dispatcher", reason="python-osc (the live extra) is not installed")
    from pythonosc.osc_server import ThreadingOSCUDPServer

    Dispatcher = dispatch.Dispatcher

    received: list[tuple[str, tuple]] = []
    dispatcher = Dispatcher()
    dispatcher.set_default_handler(lambda address, *args: received.append((address, args)))
    server = ThreadingOSCUDPServer(("127.0.0.1", 0), dispatcher)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield server.server_address[1], received
    server.shutdown()
    server.server_close()


def test_each_tick_sends_one_message_with_the_port_value(osc_server):
    from cogblocks.blocks import Playback
    from cogblocks.live import OSCSender

    port, received = osc_server
    data = np.random.default_rng(1).normal(0.0, 100.0, (20, 3))
    data[4, 1] = np.nan  # sent as it is
    d = Diagram()
    src = d.add("src", Playback(data, unit="mm"))
    sender = d.add("osc", OSCSender("127.0.0.1", port, "/avatar/hand"))
    d.connect(src.y, sender.u)
    compiled = d.compile(0.01)
    for _ in range(20):
        compiled.step()
    deadline = time.monotonic() + 2.0
    while len(received) < 20 and time.monotonic() < deadline:
        time.sleep(0.01)
    assert sender.samples_out == 20 and len(received) == 20
    assert {address for address, _ in received} == {"/avatar/hand"}
    got = np.array([args for _, args in received])
    # OSC floats are 32-bit; UDP on loopback keeps the order
    np.testing.assert_array_equal(got, data.astype(np.float32))
    sender.close()
    with pytest.raises(ValueError, match="osc: the sender is closed"):
        compiled.step()


def test_constructor_refuses_what_osc_cannot_address():
    pytest.importorskip("pythonosc", reason="python-osc (the live extra) is not installed")
    from cogblocks.live import OSCSender

    with pytest.raises(ValueError, match=r"port must be an integer in \[1, 65535\], got 70000"):
        OSCSender("127.0.0.1", 70000, "/a")
    with pytest.raises(ValueError, match="address must start with '/' and hold no space or '#', got 'avatar'"):
        OSCSender("127.0.0.1", 9000, "avatar")
    with pytest.raises(ValueError, match="host must be a non-empty string, got ''"):
        OSCSender("", 9000, "/a")
