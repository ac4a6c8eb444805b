"""C3D motion-capture files (Vicon, Qualisys, OptiTrack exports), read and written with ezc3d.

:func:`load_c3d` returns a :class:`~cogblocks.data.markers.MarkerRecording`: points in mm whatever
the file's ``POINT:UNITS`` (m, cm or mm), a sample with a negative residual (the tracker's mark of
an occluded marker) as NaN, the file's rate and time vector, the marker names and the file's events
(``EVENT:LABELS`` / ``EVENT:TIMES``, e.g. the start of a condition). :func:`write_c3d` writes such
a recording back, for tests, examples and synthetic sessions. Both need the ``recordings`` extra
(``pip install 'cogblocks[recordings]'``).
"""

from __future__ import annotations

import os
import struct
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from cogblocks.data.formats import DataFormatError, existing_file
from cogblocks.data.markers import MarkerRecording
from cogblocks.data.units import LENGTH_UNITS, to_mm

__all__ = ["load_c3d", "write_c3d"]

_BLOCK = 512  # bytes of a C3D header or parameter block


def _ezc3d() -> Any:
    try:
        import ezc3d
    except ImportError as error:
        raise ImportError("reading C3D files needs ezc3d: pip install 'cogblocks[recordings]'") from error
    return ezc3d


def load_c3d(
    path: str | os.PathLike,
    markers: Sequence[str] | None = None,
    *,
    resample: float | None = None,
) -> MarkerRecording:
    """Read the marker trajectories of a C3D file.

    Parameters
    ----------
    path : str or os.PathLike
        The C3D file.
    markers : sequence of str, optional
        The markers to keep, in that order (all by default). A name matches a label exactly, or
        the part after ``:`` of exactly one label (Vicon writes ``Subject:Marker``).
    resample : float, optional
        A grid step in s (0.01 for the diagrams' 10 ms tick): the points are interpolated onto it
        by :meth:`MarkerRecording.resampled`, gaps left as NaN. By default the file's own samples.

    Returns
    -------
    MarkerRecording
        Points in mm, NaN where occluded; ``t`` from the file's first frame (frame ``f`` at
        ``f / rate`` s, the first frame numbered 0, as C3D event times are counted).

    Raises
    ------
    FileNotFoundError, IsADirectoryError
        If ``path`` is not a file.
    DataFormatError
        If the file is not C3D, is shorter than its header says (truncated), has no points, a
        ``POINT:UNITS`` that is not a length, or lacks a requested marker (the message lists those
        it has).
    """
    file = existing_file(path)
    ezc3d = _ezc3d()
    try:
        c3d = ezc3d.c3d(str(file))
    except (RuntimeError, OSError, ValueError) as error:
        raise DataFormatError(f"{file}: not a readable C3D file ({error})") from error
    parameters = c3d["parameters"]
    raw = c3d["data"]["points"]
    n_frames = raw.shape[2] if raw.ndim == 3 else 0
    if raw.ndim != 3 or raw.shape[1] == 0 or n_frames == 0:
        raise DataFormatError(f"{file}: the file holds no 3D points (no markers or no frames)")
    expected = _header_frames(file)
    if expected is not None and n_frames < expected:
        raise DataFormatError(f"{file}: truncated: the header announces {expected} frames, the file holds {n_frames}")
    labels = _labels(parameters, raw.shape[1])
    unit = _value(parameters, "POINT", "UNITS", ["mm"])
    unit = unit[0] if len(unit) and str(unit[0]).strip() else "mm"  # the C3D standard's default
    try:
        scale = to_mm(unit, f"{file}: POINT:UNITS")
    except ValueError as error:
        raise DataFormatError(str(error)) from None
    points = np.array(raw[:3], dtype=np.float64).transpose(2, 1, 0) * scale  # (frames, markers, 3)
    residuals = c3d["data"]["meta_points"].get("residuals")
    if residuals is not None and residuals.size:
        points[np.asarray(residuals[0]).T < 0] = np.nan
    rate = float(c3d["header"]["points"]["frame_rate"])
    if not rate > 0:
        raise DataFormatError(f"{file}: the point rate is {rate:g} Hz, expected a positive rate")
    first = int(c3d["header"]["points"]["first_frame"])
    recording = MarkerRecording(
        points, (first + np.arange(n_frames)) / rate, rate, labels, _events(parameters), str(file)
    )
    if markers is not None:
        recording = recording.select([_match(file, name, labels) for name in markers])
    return recording if resample is None else recording.resampled(resample)


def write_c3d(
    path: str | os.PathLike,
    points: np.ndarray,
    markers: Sequence[str],
    rate: float,
    *,
    unit: str = "mm",
    events: Sequence[tuple[str, float]] = (),
) -> None:
    """Write marker trajectories to a C3D file (NaN samples are written as occluded).

    Parameters
    ----------
    path : str or os.PathLike
        The file to write.
    points : numpy.ndarray, shape (n_frames, n_markers, 3)
        Positions in ``unit``; NaN where a marker is not seen.
    markers : sequence of str
        One name per marker.
    rate : float
        Frames per second.
    unit : {"m", "cm", "mm"}
        The file's ``POINT:UNITS``.
    events : sequence of (str, float)
        (label, time in s) pairs written as ``EVENT:LABELS`` and ``EVENT:TIMES``.
    """
    ezc3d = _ezc3d()
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 3 or p.shape[2] != 3 or p.shape[1] != len(markers) or p.shape[0] == 0:
        raise ValueError(f"write_c3d: points must have shape (n_frames >= 1, {len(markers)}, 3), got {p.shape}")
    if unit not in LENGTH_UNITS:
        raise ValueError(f"write_c3d: unit must be one of {', '.join(LENGTH_UNITS)}, got {unit!r}")
    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [float(rate)]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = tuple(markers)
    c3d["parameters"]["POINT"]["UNITS"]["value"] = [unit]
    seen = np.isfinite(p).all(axis=2)  # (frames, markers)
    data = np.ones((4, p.shape[1], p.shape[0]))
    data[:3] = np.where(seen[..., None], p, 0.0).transpose(2, 1, 0)
    c3d["data"]["points"] = data
    residuals = np.where(seen, 0.0, -1.0).T[None]
    c3d["data"]["meta_points"] = {"residuals": residuals, "camera_masks": np.zeros((7, *seen.T.shape), dtype=bool)}
    if events:
        times = np.array([[0.0] * len(events), [float(time) for _, time in events]])
        c3d.add_parameter("EVENT", "USED", [len(events)])
        c3d.add_parameter("EVENT", "LABELS", [label for label, _ in events])
        c3d.add_parameter("EVENT", "CONTEXTS", ["General"] * len(events))
        c3d.add_parameter("EVENT", "TIMES", times)
    c3d.write(str(path))


def _header_frames(file: Path) -> int | None:
    """Frames the header announces (last − first + 1), or None where the 16-bit field cannot say."""
    with open(file, "rb") as stream:
        header = stream.read(_BLOCK)
        if len(header) < 12:
            return None
        stream.seek((header[0] - 1) * _BLOCK + 3)
        processor = stream.read(1)
    order = ">" if processor == b"\x56" else "<"  # 86: MIPS (big-endian); 84 Intel and 85 DEC are little-endian
    first, last = struct.unpack(order + "HH", header[6:10])
    if last >= 0xFFFF or last < first:  # long recordings overflow the header's field
        return None
    return last - first + 1


def _value(parameters: dict, group: str, name: str, default: Any) -> Any:
    return parameters.get(group, {}).get(name, {}).get("value", default)


def _labels(parameters: dict, n: int) -> tuple[str, ...]:
    labels = list(_value(parameters, "POINT", "LABELS", []))
    for k in range(2, 10):  # more than 255 markers continue in LABELS2, LABELS3, ...
        labels += list(_value(parameters, "POINT", f"LABELS{k}", []))
    labels = [str(label).strip() for label in labels[:n]]
    return tuple(labels + [f"marker{i}" for i in range(len(labels), n)])


def _match(file: Path, name: str, labels: tuple[str, ...]) -> str:
    if name in labels:
        return name
    suffixed = [label for label in labels if label.rpartition(":")[2] == name]
    if len(suffixed) == 1:
        return suffixed[0]
    raise DataFormatError(f"{file}: no marker {name!r} (markers: {', '.join(labels)})")


def _events(parameters: dict) -> list[tuple[str, float]]:
    labels = [str(label).strip() for label in _value(parameters, "EVENT", "LABELS", [])]
    times = np.asarray(_value(parameters, "EVENT", "TIMES", np.zeros((2, 0))), dtype=np.float64)
    if not labels or times.ndim != 2 or times.shape[0] != 2:
        return []
    seconds = 60.0 * times[0] + times[1]  # EVENT:TIMES holds (minutes, seconds) pairs
    return list(zip(labels, seconds[: len(labels)].tolist(), strict=False))
