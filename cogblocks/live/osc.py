"""OSC output: send a port to an avatar engine (Unity, Unreal, ...) as an Open Sound Control message."""

from __future__ import annotations

import math

from pythonosc.udp_client import SimpleUDPClient

from cogblocks.sim import Block
from cogblocks.sim.params import positive_int

__all__ = ["OSCSender"]


class OSCSender(Block):
    """Send the input to ``host:port`` as one OSC message per tick, one float argument per element.

    Ports
    -----
    u : input, any shape, float64, any unit
        The value to send (flattened in C order).

    Parameters
    ----------
    host : str
        Receiver's address (an IP address or a host name).
    port : int
        Receiver's UDP port (1-65535).
    address : str
        OSC address pattern of the messages, starting with ``/`` (``"/avatar/arm"``).

    Attributes
    ----------
    samples_out : int
        Messages sent so far.

    Notes
    -----
    Bad data policy: values are sent as they are; OSC floats carry NaN and inf, so a receiver that
    cannot take them needs a hold or a substitute upstream.
    """

    def __init__(self, host: str, port: int, address: str, *, period: float | None = None) -> None:
        super().__init__(period=period)
        if not isinstance(host, str) or not host:
            raise ValueError(f"OSCSender: host must be a non-empty string, got {host!r}")
        self.host = host
        self.port = positive_int(self, "port", port)
        if self.port > 65535:
            raise ValueError(f"OSCSender: port must be an integer in [1, 65535], got {port!r}")
        if not isinstance(address, str) or not address.startswith("/") or any(c in address for c in " #"):
            raise ValueError(f"OSCSender: address must start with '/' and hold no space or '#', got {address!r}")
        self.address = address
        self.add_input("u", shape=None, unit=None, wrapped=None)
        self.client: SimpleUDPClient | None = None
        self.samples_out = 0

    def setup(self) -> None:
        if math.prod(self.u.spec.shape) == 0:
            raise self._fail(f"cannot send an empty input (shape {self.u.spec.shape})")
        self.client = SimpleUDPClient(self.host, self.port)

    def close(self) -> None:
        """Close the socket (the block cannot run afterwards)."""
        if self.client is not None:
            self.client.close()
            self.client = None

    def output(self, k: int) -> None:
        if self.client is None:
            raise self._fail("the sender is closed")
        self.client.send_message(self.address, [float(v) for v in self.u.value.ravel()])
        self.samples_out += 1
