"""One entry point for recorded marker trajectories: a C3D or an XDF file, on the diagrams' tick grid."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from cogblocks.data.c3d import load_c3d
from cogblocks.data.loaders import DataFormatError
from cogblocks.data.markers import MarkerRecording
from cogblocks.data.xdf import load_xdf_markers
from cogblocks.sim.timing import BASE_STEP

__all__ = ["RECORDING_SUFFIXES", "load_recording"]

RECORDING_SUFFIXES = (".c3d", ".xdf")


def load_recording(
    path: str | os.PathLike, markers: Sequence[str] | None = None, *, dt: float = BASE_STEP, unit: str | None = None
) -> MarkerRecording:
    """Read a C3D (:func:`~cogblocks.data.c3d.load_c3d`) or XDF (:func:`~cogblocks.data.xdf.load_xdf_markers`)
    file's markers, resampled onto a grid of step ``dt`` (gaps NaN), positions in mm.

    ``unit`` is the length unit of XDF channels that declare none (a C3D file always declares one).

    Raises
    ------
    DataFormatError
        If the suffix is neither ``.c3d`` nor ``.xdf``, or as the reader does.
    """
    suffix = Path(path).suffix.lower()
    if suffix == ".c3d":
        return load_c3d(path, markers, resample=dt)
    if suffix == ".xdf":
        return load_xdf_markers(path, markers, dt=dt, unit=unit)
    raise DataFormatError(f"{path}: expected a recording ending in {' or '.join(RECORDING_SUFFIXES)}, got {suffix!r}")
