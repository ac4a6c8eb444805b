"""Write XDF files (the Lab Streaming Layer's recording format, read by pyxdf): one stream per LSL stream.

The file holds a FileHeader chunk, then per stream a StreamHeader (XML: name, type, channel count and
format, nominal rate, source id, channel labels and units), its Samples chunks (time stamps on the
stream's own clock), its ClockOffset chunks (stream clock to recorder clock, as LSL measures them) and a
StreamFooter. The file is written to a temporary file next to the target and renamed when complete, so a
failure never leaves a half-written file under the target name; when the target folder cannot take it,
the file goes to the system's temporary folder and the error names that path.
"""

from __future__ import annotations

import os
import struct
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["FORMATS", "RecordingError", "XDFStream", "write_xdf"]

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

    def channel_count(self) -> int:
        """Channels per sample."""
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


def _samples(sid: bytes, stream: XDFStream, channels: int) -> Iterable[bytes]:
    stamps = np.asarray(stream.stamps, dtype="<f8")
    n = len(stamps)
    code = FORMATS[stream.channel_format]
    if code is not None:
        values = np.asarray(stream.values).reshape(n, channels).astype(code)
        row = np.dtype([("nbytes", "u1"), ("stamp", "<f8"), ("x", code, (channels,))])
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
                for text in stream.values[i]:
                    raw = str(text).encode("utf-8")
                    parts.append(_varlen(len(raw)) + raw)
            body = b"".join(parts)
        yield _chunk("samples", sid + _varlen(stop - start) + body)


def _footer(stream: XDFStream) -> bytes:
    info = ET.Element("info")
    n = len(stream.stamps)
    _text(info, "first_timestamp", repr(float(stream.stamps[0])) if n else "0")
    _text(info, "last_timestamp", repr(float(stream.stamps[-1])) if n else "0")
    _text(info, "sample_count", n)
    offsets = ET.SubElement(info, "clock_offsets")
    for time, value in stream.clock_offsets:
        offset = ET.SubElement(offsets, "offset")
        _text(offset, "time", repr(float(time)))
        _text(offset, "value", repr(float(value)))
    return _xml(info)


def _write(f, streams: Sequence[XDFStream]) -> None:
    f.write(b"XDF:")
    info = ET.Element("info")
    _text(info, "version", "1.0")
    f.write(_chunk("file", _xml(info)))
    for i, stream in enumerate(streams, start=1):
        if stream.channel_format not in FORMATS:
            raise ValueError(
                f"write_xdf: stream {stream.name!r} has channel_format {stream.channel_format!r}; "
                f"allowed: {', '.join(FORMATS)}"
            )
        sid = struct.pack("<I", i)
        channels = stream.channel_count()
        f.write(_chunk("stream", sid + _header(stream, channels)))
        for chunk in _samples(sid, stream, channels):
            f.write(chunk)
        for time, value in stream.clock_offsets:
            f.write(_chunk("offset", sid + struct.pack("<dd", time, value)))
        f.write(_chunk("footer", sid + _footer(stream)))


def write_xdf(path: str | os.PathLike, streams: Sequence[XDFStream]) -> Path:
    """Write ``streams`` to the XDF file ``path`` and return it.

    Raises
    ------
    RecordingError
        If ``path`` could not be written; the recording was then written to a temporary file named in the
        message (``error.saved``), or, if even that failed, nowhere (``saved`` is None).
    """
    path = Path(path)
    partial = None
    try:
        handle, partial = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".partial", dir=path.parent)
        with os.fdopen(handle, "wb") as f:
            _write(f, streams)
            f.flush()
            os.fsync(f.fileno())
        os.replace(partial, path)
        return path
    except OSError as exc:
        problem = exc
    finally:
        if partial is not None and os.path.exists(partial):
            os.unlink(partial)  # a bad stream or a full disk: no partial file left next to the target
    handle, rescue = tempfile.mkstemp(prefix=f"{path.stem}-", suffix=".xdf")
    try:
        with os.fdopen(handle, "wb") as f:
            _write(f, streams)
    except OSError as exc:
        raise RecordingError(
            f"could not write the recording to {path} ({problem}) nor to {rescue} ({exc})", None
        ) from exc
    raise RecordingError(
        f"could not write the recording to {path} ({problem}); it was written to {rescue}", Path(rescue)
    )
