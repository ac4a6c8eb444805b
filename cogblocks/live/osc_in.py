"""OSCReceiver: Open Sound Control messages (a headset, a game engine) resampled onto the diagram's step."""

from __future__ import annotations

import collections
import threading
import time
from typing import Unpack

import numpy as np
from pythonosc.dispatcher import Dispatcher
from pythonosc.osc_server import BlockingOSCUDPServer

from cogblocks.live.timed import InletOptions, StreamHeader, TimedInlet

__all__ = ["OSCReceiver"]

_QUEUE = 4096  # messages kept between two ticks; older ones are dropped first


class OSCReceiver(TimedInlet):
    """OSC messages on a UDP port, one value per tick, with the policy of :class:`~cogblocks.live.LSLInlet`.

    A server on ``host:port`` (127.0.0.1 by default: this machine only) takes the messages sent to
    ``address``, one number per channel, and stamps each with its arrival time on ``time.monotonic()``
    (the clock that LSL's ``local_clock`` reads on Linux). Each tick turns what arrived into one value
    (``mode`` ``latest`` or ``interpolate``, ``lag``, ``hold``), exactly as :class:`~cogblocks.live.LSLInlet`
    does, and a session recording keeps the messages as a stream named after ``address``.

    Ports
    -----
    y : output, ``shape``, float64, ``unit``, ``wrapped``
    age_ms : output, scalar, ms
    fresh : output, scalar, bool
        As :class:`~cogblocks.live.LSLInlet`'s.

    Parameters
    ----------
    address : str
        OSC address of the messages, starting with ``/`` (``"/headset/phase"``).
    port : int
        UDP port to listen on (0: any free port, see :attr:`port` once compiled).
    host : str
        Address to listen on.
    shape, unit, wrapped, mode, lag, hold, record
        As :class:`~cogblocks.live.LSLInlet`'s.
    source_unit : str, optional
        The messages' unit (OSC declares none): a length (m, cm, mm) converts to ``unit``; without it the
        values are taken in ``unit``, with a warning.

    Attributes
    ----------
    port : int
        The port listened on.
    samples_in : int
        Messages received so far.
    rejected : int
        Messages to ``address`` with the wrong number of arguments or a non-number (each counts as a lost
        sample: NaN).

    Notes
    -----
    Bad data policy: as :class:`~cogblocks.live.LSLInlet`'s: a non-finite value, or a message that does not
    fit the port, is a NaN sample; a tick with no sample recent enough gives NaN. Messages to other
    addresses are ignored.
    """

    _stream_kind = "OSC address"

    def __init__(
        self,
        address: str,
        port: int = 0,
        *,
        host: str = "127.0.0.1",
        **options: Unpack[InletOptions],
    ) -> None:
        if not isinstance(address, str) or not address.startswith("/") or any(c in address for c in " #*?[]{}"):
            raise ValueError(
                f"OSCReceiver: address must start with '/' and hold no space, '#' or pattern, got {address!r}"
            )
        if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
            raise ValueError(f"OSCReceiver: port must be an integer in [0, 65535], got {port!r}")
        if not isinstance(host, str) or not host:
            raise ValueError(f"OSCReceiver: host must be a non-empty string, got {host!r}")
        super().__init__(**options)
        self.address = address
        self.port = port
        self.host = host
        self.rejected = 0
        self._queue: collections.deque = collections.deque(maxlen=_QUEUE)
        self._thread: threading.Thread | None = None

    def _on_message(self, address: str, *args: object) -> None:
        stamp = time.monotonic()
        try:
            values = np.array(args, dtype=np.float64)
        except (TypeError, ValueError):
            values = np.empty(0)
        if values.shape != (self.channels,):
            self.rejected += 1
            values = np.full(self.channels, np.nan)
        self._queue.append((stamp, values))

    def _open(self) -> StreamHeader:
        header = StreamHeader(
            name=self.address,
            type="OSC",
            channel_count=self.channels,
            channel_format="double64",
            nominal_srate=0.0,
            source_id=f"osc://{self.host}:{self.port}{self.address}",
            units=[""] * self.channels,
        )
        self.scale = self._check_stream(header)
        dispatcher = Dispatcher()
        dispatcher.map(self.address, self._on_message)
        try:
            server = BlockingOSCUDPServer((self.host, self.port), dispatcher)
        except OSError as exc:
            raise self._fail(f"cannot listen on {self.host}:{self.port} for OSC ({exc})") from None
        self.port = server.server_address[1]
        header.source_id = f"osc://{self.host}:{self.port}{self.address}"
        self._thread = threading.Thread(target=server.serve_forever, name=f"osc {self.address}", daemon=True)
        self._thread.start()
        self._handle = server
        return header

    def _release(self, handle: BlockingOSCUDPServer) -> None:
        handle.shutdown()
        handle.server_close()
        self._thread.join()

    def _clock(self) -> float:
        return time.monotonic()

    def _receive(self) -> list[tuple[np.ndarray, np.ndarray]]:
        stamps, values = [], []
        while self._queue:
            stamp, value = self._queue.popleft()
            stamps.append(stamp)
            values.append(value)
        if not stamps:
            return []
        return [(np.array(stamps), np.array(values).reshape(len(stamps), self.channels))]
