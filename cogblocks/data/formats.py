"""What the readers of reach-to-grasp libraries share: their error, the checks of a file and the padding."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import numpy as np

from cogblocks.data.reach import ReachLibrary

__all__ = [
    "DT_HINT",
    "LABEL_HINT",
    "DataFormatError",
    "PathLike",
    "existing_file",
    "is_real",
    "library_from_movements",
    "unreadable",
]

LABEL_HINT = "; if the fear label has another name, map it with label_field=NAME (command line: --label-field NAME)"
DT_HINT = "; give the sampling step with dt=SECONDS (command line: --dt SECONDS)"


class DataFormatError(ValueError):
    """A data file exists but its content does not follow the expected format."""


PathLike = str | os.PathLike


def existing_file(path: PathLike) -> Path:
    """``path`` as a Path, after checking that it is a non-empty file."""
    file = Path(path)
    if file.is_dir():
        raise IsADirectoryError(errno.EISDIR, f"{os.strerror(errno.EISDIR)}, expected a file", str(path))
    if not file.is_file():
        raise FileNotFoundError(errno.ENOENT, os.strerror(errno.ENOENT), str(path))
    if file.stat().st_size == 0:
        raise DataFormatError(f"{file}: empty file")
    return file


def unreadable(error: Exception) -> str:
    """Why numpy refused an array, without numpy's advice to load pickled data (unsafe)."""
    if "pickle" in str(error).lower():
        return "it holds pickled Python objects, which are never loaded: loading them can run arbitrary code"
    return str(error)


def is_real(dtype: np.dtype) -> bool:
    """Booleans, integers and real floats (not complex, text or objects)."""
    return np.issubdtype(dtype, np.bool_) or np.issubdtype(dtype, np.integer) or np.issubdtype(dtype, np.floating)


def library_from_movements(
    file: Path,
    velocities: list[np.ndarray],
    positions: list[np.ndarray],
    labels: dict[str, list[int]],
    max_len: int,
    dt: float,
    scale: float = 1.0,
) -> ReachLibrary:
    """Pad movements of their own lengths (velocity with zeros, position holding its last value), times ``scale``."""
    n = len(velocities)
    velocity = np.zeros((n, max_len, 3))
    position = np.zeros((n, max_len, 3))
    for i, (v, p) in enumerate(zip(velocities, positions, strict=True)):
        velocity[i, : len(v)] = v
        position[i, : len(p)] = p
        position[i, len(p) :] = p[-1]
    try:
        return ReachLibrary(
            velocity=velocity * scale,
            position=position * scale,
            length=np.array([len(v) for v in velocities], dtype=np.int64),
            dt=dt,
            **{name: np.array(values, dtype=np.int64) for name, values in labels.items()},
        )
    except ValueError as error:
        raise DataFormatError(f"{file}: {error}") from error
