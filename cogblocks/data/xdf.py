"""XDF recordings (LabRecorder, Lab Streaming Layer) of marker positions, read with pyxdf.

:func:`load_xdf_markers` accepts the two layouts a group session is recorded in:

- **a stream per participant**: the stream's name is the marker's name, its three numeric channels
  are x, y, z (in the order of their labels ``x``/``y``/``z`` when they have such labels);
- **labelled channels**: streams whose channels are labelled ``NAME_x``, ``NAME_y``, ``NAME_z``
  (separator ``_``, ``:``, ``.``, ``-`` or a blank; axis in any case), so one stream can carry
  several markers.

Each channel's ``unit`` (``desc/channels/channel/unit``: m, cm, mm, or spelled out) is converted to
mm; a channel that declares none takes ``unit=`` and, if that is not given either, is taken as mm
with a warning. Every stream is interpolated onto one grid (``t = 0`` when the last stream has
started), gaps left NaN. String streams (type ``Markers``) give the events, e.g. the start of a
condition. :func:`~cogblocks.data.xdf_write.write_xdf` writes such a file (re-exported here).
"""

from __future__ import annotations

import os
import re
import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np

from cogblocks.data.formats import DataFormatError, existing_file
from cogblocks.data.markers import MarkerRecording
from cogblocks.data.units import to_mm
from cogblocks.data.xdf_write import write_xdf
from cogblocks.sim.timing import BASE_STEP

__all__ = ["load_xdf_markers", "write_xdf"]

_AXIS = re.compile(r"^(?P<name>.+?)[_:.\- ](?P<axis>[xyzXYZ])$")


def load_xdf_markers(
    path: str | os.PathLike,
    markers: Sequence[str] | None = None,
    *,
    dt: float = BASE_STEP,
    unit: str | None = None,
) -> MarkerRecording:
    """Read marker positions and events from an XDF file onto one time grid.

    Parameters
    ----------
    path : str or os.PathLike
        The XDF file.
    markers : sequence of str, optional
        The markers to keep, in that order (by default every one found).
    dt : float
        Step of the common grid in s (0.01: the diagrams' tick).
    unit : str, optional
        Length unit of channels that declare none.

    Raises
    ------
    DataFormatError
        If the file is not XDF, has no marker stream in either layout, lacks a requested marker
        (the message lists those found) or declares a unit that is not a length.
    """
    file = existing_file(path)
    try:
        import pyxdf
    except ImportError as error:
        raise ImportError("reading XDF files needs pyxdf: pip install 'cogblocks[recordings]'") from error
    try:
        streams, _ = pyxdf.load_xdf(str(file))
    except Exception as error:  # pyxdf raises whatever its parser met (struct, XML, EOF errors)
        raise DataFormatError(f"{file}: not a readable XDF file ({type(error).__name__}: {error})") from error
    found: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    warned: set[str] = set()
    events: list[tuple[str, float]] = []
    for stream in streams:
        info = stream["info"]
        name = _first(info.get("name"), "stream")
        stamps = np.asarray(stream["time_stamps"], dtype=np.float64)
        if _first(info.get("channel_format"), "") == "string":
            events += [
                (str(sample[0]), float(time)) for sample, time in zip(stream["time_series"], stamps, strict=True)
            ]
            continue
        values = np.asarray(stream["time_series"], dtype=np.float64)
        if values.ndim != 2 or len(stamps) < 2:
            continue
        for marker, columns, units in _markers_of(name, _channels(info), values.shape[1]):
            found[marker] = (stamps, values[:, columns] * _scales(file, name, units, unit, warned))
    if not found:
        raise DataFormatError(
            f"{file}: no marker stream (expected a 3-channel stream per participant, "
            "or channels labelled NAME_x, NAME_y, NAME_z)"
        )
    names = list(found) if markers is None else list(markers)
    unknown = [m for m in names if m not in found]
    if unknown:
        raise DataFormatError(f"{file}: no marker(s) {', '.join(map(repr, unknown))} (markers: {', '.join(found)})")
    start = max(found[m][0][0] for m in names)
    stop = min(found[m][0][-1] for m in names)
    if stop <= start:
        raise DataFormatError(f"{file}: the streams of {', '.join(names)} do not overlap in time")
    grid = start + dt * np.arange(int(np.floor((stop - start) / dt + 1e-9)) + 1)
    points = np.full((len(grid), len(names), 3), np.nan)
    for k, m in enumerate(names):
        stamps, values = found[m]
        order = np.argsort(stamps, kind="stable")
        single = MarkerRecording(values[order][:, None], stamps[order], 1.0 / dt, (m,), (), str(file))
        points[:, k] = single.on_grid(grid)[:, 0]
    shifted = [(label, time - start) for label, time in events]
    return MarkerRecording(points, grid - start, 1.0 / dt, tuple(names), shifted, str(file))


def _first(value: Any, default: str) -> str:
    while isinstance(value, list):
        value = value[0] if value else None
    return default if value is None else str(value)


def _channels(info: dict) -> list[dict]:
    desc = info.get("desc") or [None]
    if not isinstance(desc[0], dict):
        return []
    groups = desc[0].get("channels") or [None]
    return (groups[0] or {}).get("channel", []) if isinstance(groups[0], dict) else []


def _markers_of(stream: str, channels: list[dict], n: int) -> list[tuple[str, list[int], list[str | None]]]:
    """(marker, its x/y/z columns, their declared units) for each marker the stream carries."""
    labels = [_first(c.get("label"), "") for c in channels] if len(channels) == n else [""] * n
    units = [(_first(c.get("unit"), "") or None) for c in channels] if len(channels) == n else [None] * n
    axes: dict[str, dict[str, int]] = {}
    for column, label in enumerate(labels):
        match = _AXIS.match(label.strip())
        if match:
            axes.setdefault(match["name"], {})[match["axis"].lower()] = column
    found = [(name, [a[x] for x in "xyz"]) for name, a in axes.items() if set(a) == set("xyz")]
    if not found and n == 3:  # a stream per participant
        by_label = {label.strip().lower(): c for c, label in enumerate(labels)}
        columns = [by_label[x] for x in "xyz"] if set("xyz") <= set(by_label) else [0, 1, 2]
        found = [(stream, columns)]
    return [(name, columns, [units[c] for c in columns]) for name, columns in found]


_SPELLED = {
    "millimeters": "mm",
    "millimetres": "mm",
    "centimeters": "cm",
    "centimetres": "cm",
    "meters": "m",
    "metres": "m",
}


def _scales(file: Any, stream: str, declared: list[str | None], default: str | None, warned: set[str]) -> np.ndarray:
    """Millimetres per unit of each channel (a stream that declares none is named once in a warning)."""
    if None in declared and default is None and stream not in warned:
        warned.add(stream)
        warnings.warn(f"{file}: stream {stream!r} declares no unit: taken as mm (give unit=...)", stacklevel=3)
    out = []
    for unit in declared:
        unit = _SPELLED.get(unit.strip().lower(), unit) if unit is not None else default or "mm"
        try:
            out.append(to_mm(unit, f"{file}: stream {stream!r}"))
        except ValueError as error:
            raise DataFormatError(str(error)) from None
    return np.array(out)
