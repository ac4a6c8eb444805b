"""LSLOutlet: publish a port as a Lab Streaming Layer stream, for an avatar engine or a recorder."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pylsl

from cogblocks.live.inlet import stream_name_arg
from cogblocks.sim import Block
from cogblocks.sim.params import flag

__all__ = ["LSLOutlet"]


class LSLOutlet(Block):
    """Publish a port as a Lab Streaming Layer stream, one sample per tick.

    The stream is created when the diagram is compiled, with one channel per element of the input,
    the input's unit in every channel's description, and a nominal rate of one sample per block
    period (100 Hz at the usual 10 ms step). Each tick pushes ``u`` stamped with
    ``pylsl.local_clock()``.

    Ports
    -----
    u : input, any shape, float64, any unit
        The value to publish (flattened in C order).

    Parameters
    ----------
    name : str
        The stream's name.
    stream_type : str
        The stream's content type (``"Phase"``, ``"MoCap"``, ...).
    source_id : str, optional
        A unique id of the source, which lets receivers recover the stream after a restart
        (default: ``cogblocks-<name>``).
    channel_names : list of str, optional
        One label per channel (default ``<name>0``, ``<name>1``, ...).
    record : bool
        Keep every sample pushed with its time stamp (what a session file records, see :meth:`session`).

    Attributes
    ----------
    samples_out : int
        Samples pushed so far.
    last_timestamp : float
        The LSL timestamp of the last sample pushed.

    Notes
    -----
    Bad data policy: values are published as they are; a NaN or inf reaches the receivers (LSL
    carries IEEE floats). Put a hold or a substitute upstream for receivers that cannot take them.
    """

    def __init__(
        self,
        name: str,
        *,
        stream_type: str = "cogblocks",
        source_id: str | None = None,
        channel_names: list[str] | None = None,
        record: bool = False,
        period: float | None = None,
    ) -> None:
        super().__init__(period=period)
        owner = type(self).__name__
        self.stream_name = stream_name_arg(owner, "name", name)
        self.stream_type = stream_name_arg(owner, "stream_type", stream_type)
        self.source_id = stream_name_arg(owner, "source_id", source_id or f"cogblocks-{name}")
        if channel_names is not None and not (
            isinstance(channel_names, (list, tuple)) and all(isinstance(c, str) and c for c in channel_names)
        ):
            raise ValueError(f"{owner}: channel_names must be a list of non-empty strings, got {channel_names!r}")
        self.channel_names = None if channel_names is None else list(channel_names)
        self.add_input("u", shape=None, unit=None, wrapped=None)
        self.record = flag(self, "record", record)
        #: Do not publish (a replayed session): count and record the samples only.
        self.offline = False
        self.outlet: pylsl.StreamOutlet | None = None
        self.samples_out = 0
        self.last_timestamp = math.nan
        self.labels: list[str] = []
        self._log: list[tuple[float, np.ndarray]] = []

    def setup(self) -> None:
        spec = self.u.spec
        n = math.prod(spec.shape)
        if n == 0:
            raise self._fail(f"cannot publish an empty input (shape {spec.shape})")
        labels = self.channel_names or [f"{self.stream_name}{i}" for i in range(n)]
        if len(labels) != n:
            raise self._fail(f"{len(labels)} channel name(s) for an input of {n} channel(s) (shape {spec.shape})")
        self.labels = list(labels)
        if self.offline:
            return
        info = pylsl.StreamInfo(self.stream_name, self.stream_type, n, 1.0 / self.dt, pylsl.cf_double64, self.source_id)
        channels = info.desc().append_child("channels")
        for label in labels:
            channel = channels.append_child("channel")
            channel.append_child_value("label", label)
            channel.append_child_value("unit", spec.unit)
            channel.append_child_value("type", self.stream_type)
        meta = info.desc().append_child("cogblocks")
        meta.append_child_value("shape", ",".join(map(str, spec.shape)))
        meta.append_child_value("wrapped", str(bool(spec.wrapped)).lower())
        self.outlet = pylsl.StreamOutlet(info)

    def close(self) -> None:
        """Withdraw the stream (the block cannot run afterwards)."""
        self.outlet = None  # pylsl destroys the outlet with its last reference

    def output(self, k: int) -> None:
        if self.offline:
            stamp = math.nan
        elif self.outlet is None:
            raise self._fail("the stream is closed")
        else:
            stamp = pylsl.local_clock()
            self.outlet.push_sample(self.u.value.ravel(), stamp)
        if self.record:
            self._log.append((stamp, self.u.value.ravel().astype(np.float64)))
        self.last_timestamp = stamp
        self.samples_out += 1

    def session(self) -> dict[str, Any]:
        """What a session file keeps of this outlet: every sample pushed with ``record=True``, and its stream."""
        stamps = np.array([s for s, _ in self._log], dtype=np.float64)
        values = np.array([v for _, v in self._log], dtype=np.float64).reshape(len(stamps), len(self.labels))
        return {"stamps": stamps, "values": values}
