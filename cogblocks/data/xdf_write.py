"""Write XDF files (the Lab Streaming Layer's recording format, read by pyxdf), whole or as they come.

A file holds a FileHeader chunk, then per stream a StreamHeader (XML: name, type, channel count and
format, nominal rate, source id, channel labels and units), its Samples chunks (time stamps on the
stream's own clock), its ClockOffset chunks (stream clock to recorder clock, as LSL measures them) and a
StreamFooter. :class:`XDFWriter` appends chunks to an open file as the samples come: after each
:meth:`~XDFWriter.flush` the file is a valid XDF file (pyxdf reads it without footers), so a process
killed mid-run loses only what came since. :func:`write_xdf` writes whole streams to a temporary file
next to the target and renames it when complete; when the target folder cannot take it, the file goes
to the system's temporary folder and the error names that path.

There is no maintained Python XDF writer (pyxdf reads only; LabRecorder is a C++ program), so this one
is tested by reading every file back with pyxdf.
"""

from __future__ import annotations

import os
import struct
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

__all__ = ["FORMATS", "RecordingError", "XDFStream", "XDFWriter", "write_whole", "write_xdf"]

#: XDF channel formats and their little-endian NumPy types.
FORMATS = {
    "float32": "<f4",
    "double64": "<f8",
    "int8": "i1",
    "int16": "<i2",
    "int32": "<i4",
    "int64": "<i8",
    "string": None,
}
_TAG = {"file": 1, "stream": 2, "samples": 3, "offset": 4, "footer": 6}
_PER_CHUNK = 1024  # samples per Samples chunk


class RecordingError(OSError):
    """A recording could not be written where asked; ``saved`` is where it was written instead (or None)."""

    def __init__(self, message: str, saved: Path | None) -> None:
        super().__init__(message)
        self.saved = saved


@dataclass
class XDFStream:
    """One stream of an XDF file.

    Parameters
    ----------
    name, type : str
        The stream's name and content type.
    stamps : numpy.ndarray, shape (n,)
        Time stamps in seconds, on the stream's clock.
    values : numpy.ndarray, shape (n, channels), or a list of lists of str for ``"string"``
        The samples.
    channel_format : str
        One of :data:`FORMATS`.
    nominal_srate : float
        Samples per second (0: irregular).
    labels, units : list of str
        One per channel (empty: none written).
    source_id, hostname : str
        As LSL gives them.
    clock_offsets : list of (float, float)
        ``(collection time, offset)`` pairs: recorder time = stream time + offset.
    desc : dict of str to str
        Extra fields written under ``<desc><cogblocks>``.
    channels : int
        Channels per sample (0: from ``values``, or from ``labels`` when there are no samples).
    """

    name: str
    type: str
    stamps: np.ndarray
    values: np.ndarray | Sequence[Sequence[str]]
    channel_format: str = "double64"
    nominal_srate: float = 0.0
    labels: list[str] = field(default_factory=list)
    units: list[str] = field(default_factory=list)
    source_id: str = ""
    hostname: str = ""
    clock_offsets: list[tuple[float, float]] = field(default_factory=list)
    desc: dict[str, str] = field(default_factory=dict)
    channels: int = 0

    def channel_count(self) -> int:
        """Channels per sample."""
        if self.channels:
            return self.channels
        if len(self.stamps) == 0:
            return max(1, len(self.labels))
        if self.channel_format == "string":
            return len(self.values[0])
        return int(np.asarray(self.values).reshape(len(self.stamps), -1).shape[1])


def _varlen(n: int) -> bytes:
    if n < 256:
        return struct.pack("<BB", 1, n)
    if n < 2**32:
        return struct.pack("<BI", 4, n)
    return struct.pack("<BQ", 8, n)


def _chunk(tag: str, content: bytes) -> bytes:
    return _varlen(len(content) + 2) + struct.pack("<H", _TAG[tag]) + content


def _xml(root: ET.Element) -> bytes:
    return b'<?xml version="1.0"?>' + ET.tostring(root, encoding="utf-8")


def _text(parent: ET.Element, tag: str, value: object) -> ET.Element:
    child = ET.SubElement(parent, tag)
    child.text = str(value)
    return child


def _header(stream: XDFStream, channels: int) -> bytes:
    info = ET.Element("info")
    for tag, value in (
        ("name", stream.name),
        ("type", stream.type),
        ("channel_count", channels),
        ("channel_format", stream.channel_format),
        ("source_id", stream.source_id),
        ("nominal_srate", repr(float(stream.nominal_srate))),
        ("version", "1.1000000000000001"),
        ("hostname", stream.hostname),
    ):
        _text(info, tag, value)
    desc = ET.SubElement(info, "desc")
    if stream.labels or stream.units:
        chans = ET.SubElement(desc, "channels")
        for i in range(channels):
            channel = ET.SubElement(chans, "channel")
            _text(channel, "label", stream.labels[i] if i < len(stream.labels) else "")
            _text(channel, "unit", stream.units[i] if i < len(stream.units) else "")
    if stream.desc:
        extra = ET.SubElement(desc, "cogblocks")
        for key, value in stream.desc.items():
            _text(extra, key, value)
    return _xml(info)


@dataclass
class _Open:
    """What the writer keeps of a stream for its footer."""

    sid: bytes
    channels: int
    channel_format: str
    first: float | None = None
    last: float = 0.0
    count: int = 0
    offsets: list[tuple[float, float]] = field(default_factory=list)


class XDFWriter:
    """An XDF file written as it goes: streams declared, then samples and clock offsets appended.

    Chunks are collected in memory and written by :meth:`flush` in one write, so the file on disk
    always ends at a chunk boundary: it is a valid XDF file after every flush, footers or not.

    Parameters
    ----------
    file : binary file
        Open for writing, at its start (the writer does not close it).
    """

    def __init__(self, file: BinaryIO) -> None:
        self.file = file
        self._streams: list[_Open] = []
        info = ET.Element("info")
        _text(info, "version", "1.0")
        self._pending = [b"XDF:", _chunk("file", _xml(info))]

    def add_stream(self, stream: XDFStream) -> int:
        """Declare ``stream`` (its header; its samples and offsets are not written) and return its index."""
        if stream.channel_format not in FORMATS:
            raise ValueError(
                f"write_xdf: stream {stream.name!r} has channel_format {stream.channel_format!r}; "
                f"allowed: {', '.join(FORMATS)}"
            )
        sid = struct.pack("<I", len(self._streams) + 1)
        channels = stream.channel_count()
        self._streams.append(_Open(sid, channels, stream.channel_format))
        self._pending.append(_chunk("stream", sid + _header(stream, channels)))
        return len(self._streams) - 1

    def samples(self, index: int, stamps: Any, values: Any) -> None:
        """Append samples to stream ``index``: ``stamps`` (n,) and ``values`` (n, channels) or rows of strings."""
        s = self._streams[index]
        stamps = np.asarray(stamps, dtype="<f8").reshape(-1)
        n = len(stamps)
        if n == 0:
            return
        code = FORMATS[s.channel_format]
        if code is not None:
            values = np.asarray(values).reshape(n, s.channels).astype(code)
            row = np.dtype([("nbytes", "u1"), ("stamp", "<f8"), ("x", code, (s.channels,))])
        for start in range(0, n, _PER_CHUNK):
            stop = min(n, start + _PER_CHUNK)
            if code is not None:
                table = np.empty(stop - start, dtype=row)
                table["nbytes"], table["stamp"], table["x"] = 8, stamps[start:stop], values[start:stop]
                body = table.tobytes()
            else:
                parts = []
                for i in range(start, stop):
                    parts.append(struct.pack("<Bd", 8, stamps[i]))
                    for text in values[i]:
                        raw = str(text).encode("utf-8")
                        parts.append(_varlen(len(raw)) + raw)
                body = b"".join(parts)
            self._pending.append(_chunk("samples", s.sid + _varlen(stop - start) + body))
        s.first = float(stamps[0]) if s.first is None else s.first
        s.last = float(stamps[-1])
        s.count += n

    def offset(self, index: int, time: float, value: float) -> None:
        """Append a clock offset to stream ``index``: recorder time = stream time + ``value`` at ``time``."""
        s = self._streams[index]
        s.offsets.append((float(time), float(value)))
        self._pending.append(_chunk("offset", s.sid + struct.pack("<dd", time, value)))

    def flush(self) -> None:
        """Write what was appended since the last flush, in one write, and flush the file."""
        if self._pending:
            data, self._pending = b"".join(self._pending), []
            self.file.write(data)
        self.file.flush()

    def finish(self, extra: dict[int, dict[str, str]] | None = None) -> None:
        """Append every stream's footer (first and last stamps, count, offsets) and flush.

        ``extra`` maps a stream's index to fields written under the footer's ``<cogblocks>``.
        """
        for index, s in enumerate(self._streams):
            info = ET.Element("info")
            _text(info, "first_timestamp", repr(s.first) if s.count else "0")
            _text(info, "last_timestamp", repr(s.last) if s.count else "0")
            _text(info, "sample_count", s.count)
            offsets = ET.SubElement(info, "clock_offsets")
            for time, value in s.offsets:
                offset = ET.SubElement(offsets, "offset")
                _text(offset, "time", repr(time))
                _text(offset, "value", repr(value))
            if extra and index in extra:
                fields = ET.SubElement(info, "cogblocks")
                for key, value in extra[index].items():
                    _text(fields, key, value)
            self._pending.append(_chunk("footer", s.sid + _xml(info)))
        self.flush()


def _as_stream(stream: XDFStream | dict[str, Any]) -> XDFStream:
    """A stream given as a dict (``name``, ``time_stamps``, ``time_series``; optional ``type``, ``labels``,
    ``unit`` for every channel, ``srate``) as an :class:`XDFStream`, on the recorder's clock."""
    if isinstance(stream, XDFStream):
        return stream
    stamps = np.asarray(stream["time_stamps"], dtype=np.float64)
    strings = not isinstance(stream["time_series"], np.ndarray)
    values = [[str(v)] for v in stream["time_series"]] if strings else np.asarray(stream["time_series"], np.float64)
    n = 1 if strings else values.shape[1]
    unit = stream.get("unit")
    return XDFStream(
        stream["name"],
        stream.get("type", "Markers" if strings else "MoCap"),
        stamps,
        values,
        channel_format="string" if strings else "double64",
        nominal_srate=float(stream.get("srate", 0)),
        labels=list(stream.get("labels") or [f"ch{c}" for c in range(n)]),
        units=[unit] * n if unit else [],
        clock_offsets=[(float(t), 0.0) for t in dict.fromkeys([*stamps[:1], *stamps[-1:]])],  # one clock segment
        channels=n,
    )


def _write(f: BinaryIO, streams: Sequence[XDFStream]) -> None:
    writer = XDFWriter(f)
    for stream in streams:
        index = writer.add_stream(stream)
        writer.samples(index, stream.stamps, stream.values)
        for time, value in stream.clock_offsets:
            writer.offset(index, time, value)
    writer.finish()


def write_xdf(path: str | os.PathLike, streams: Sequence[XDFStream | dict[str, Any]]) -> Path:
    """Write ``streams`` to the XDF file ``path`` and return it.

    Parameters
    ----------
    path : str or os.PathLike
        The file to write.
    streams : sequence of XDFStream or dict
        The streams; a dict has ``name``, ``time_stamps`` (n,) in s and ``time_series``, an (n, channels)
        float array or a list of strings for a marker stream (type ``Markers``), and optionally ``type``,
        ``labels`` (one per channel), ``unit`` (one for every channel) and ``srate`` (0 for irregular).

    Raises
    ------
    RecordingError
        If ``path`` could not be written; the recording was then written to a temporary file named in the
        message (``error.saved``), or, if even that failed, nowhere (``saved`` is None).
    ValueError
        If a stream's channel format is not one of :data:`FORMATS` (nothing is written).
    """
    streams = [_as_stream(s) for s in streams]
    for stream in streams:
        if stream.channel_format not in FORMATS:
            raise ValueError(
                f"write_xdf: stream {stream.name!r} has channel_format {stream.channel_format!r}; "
                f"allowed: {', '.join(FORMATS)}"
            )
    return write_whole(path, lambda f: _write(f, streams))


def write_whole(path: str | os.PathLike, fill: Callable[[BinaryIO], None], failed: OSError | None = None) -> Path:
    """Have ``fill(file)`` write a whole file at ``path``: to a temporary file next to it, renamed when complete.

    When ``path`` cannot take it (or ``failed`` says it could not), the file goes to the system's
    temporary folder and :class:`RecordingError` names both.
    """
    path = Path(path)
    problem = failed
    partial = None
    if problem is None:
        try:
            handle, partial = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".partial", dir=path.parent)
            with os.fdopen(handle, "wb") as f:
                fill(f)
                os.fsync(f.fileno())
            os.replace(partial, path)
            return path
        except OSError as exc:
            problem = exc
        finally:
            if partial is not None and os.path.exists(partial):
                os.unlink(partial)  # a full disk: no partial file left next to the target
    handle, rescue = tempfile.mkstemp(prefix=f"{path.stem}-", suffix=".xdf")
    try:
        with os.fdopen(handle, "wb") as f:
            fill(f)
    except OSError as exc:
        raise RecordingError(
            f"could not write the recording to {path} ({problem}) nor to {rescue} ({exc})", None
        ) from exc
    raise RecordingError(
        f"could not write the recording to {path} ({problem}); it was written to {rescue}", Path(rescue)
    )
