"""A reach-to-grasp library built from recorded trials (C3D or XDF files, one movement each) and their labels."""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cogblocks.data.formats import DataFormatError, library_from_movements
from cogblocks.data.reach import ReachLibrary
from cogblocks.data.recordings import load_recording
from cogblocks.sim.timing import BASE_STEP

__all__ = ["ReachTrial", "library_from_recordings"]


@dataclass(frozen=True)
class ReachTrial:
    """One recorded reach and its labels.

    Attributes
    ----------
    path : str or os.PathLike
        The trial's file (.c3d or .xdf), holding one movement from its start to its end.
    fear : bool
        True if the movement encodes fear (a reach towards the stimulation-paired cube).
    subject : int
        The participant's index (>= 0).
    target : int
        The cube reached for, 0 or 1, or -1 if unknown.
    """

    path: str | os.PathLike
    fear: bool
    subject: int = 0
    target: int = -1


def library_from_recordings(
    trials: Sequence[ReachTrial], marker: str, *, dt: float = BASE_STEP, max_len: int = 200
) -> ReachLibrary:
    """Build a :class:`ReachLibrary` from labelled recorded trials of one marker (the wrist).

    Each trial is read with :func:`~cogblocks.data.recordings.load_recording` onto a grid of step
    ``dt`` (positions in mm whatever the file's unit); its velocity is the central difference of
    the positions (``numpy.gradient``, one-sided at the ends), in mm/s. The library then trains and
    runs like the bundled one (``save_npz`` it for ``cogblocks run amplification --library``).

    Raises
    ------
    DataFormatError
        Naming the file: a trial with a gap (the marker lost: fill it in the tracker's software or
        leave the trial out), one longer than ``max_len`` samples, or one shorter than 2.
    """
    if not trials:
        raise ValueError("library_from_recordings: no trials")
    velocities, positions = [], []
    labels: dict[str, list[int]] = {"fear": [], "subject": [], "target": []}
    for trial in trials:
        rec = load_recording(trial.path, [marker], dt=dt)
        p = rec.points[:, 0]
        lost = np.flatnonzero(~np.isfinite(p).all(axis=1))
        if lost.size:
            raise DataFormatError(
                f"{trial.path}: marker {rec.markers[0]!r} is lost on {lost.size} tick(s) from "
                f"{rec.t[lost[0]] - rec.t[0]:.3f} s: fill the gap in the tracker's software or leave the trial out"
            )
        if not 2 <= len(p) <= max_len:
            raise DataFormatError(f"{trial.path}: {len(p)} samples at dt={dt:g} s, expected 2..max_len={max_len}")
        positions.append(p)
        velocities.append(np.gradient(p, dt, axis=0))
        labels["fear"].append(int(bool(trial.fear)))
        labels["subject"].append(int(trial.subject))
        labels["target"].append(int(trial.target))
    return library_from_movements(Path(str(trials[0].path)), velocities, positions, labels, max_len, dt)
