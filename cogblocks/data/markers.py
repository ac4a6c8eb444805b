"""Recorded marker trajectories in millimetres, with their time vector, gaps and events, and their resampling.

A :class:`MarkerRecording` is what the file readers (:func:`~cogblocks.data.c3d.load_c3d`,
:func:`~cogblocks.data.xdf.load_xdf_markers`) return: every position in mm whatever the file's unit,
a sample the tracker lost (an occluded marker) as NaN, and the events the file marks (conditions).
:meth:`MarkerRecording.resampled` puts it on the diagrams' tick grid (10 ms by default) with
``scipy.interpolate``, leaving gaps as NaN rather than bridging them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.interpolate

from cogblocks.sim.timing import BASE_STEP

__all__ = ["MarkerRecording"]


@dataclass(frozen=True)
class MarkerRecording:
    """Marker trajectories of one recording.

    Attributes
    ----------
    points : numpy.ndarray, shape (n_samples, n_markers, 3)
        Positions in mm; NaN where the marker was not seen.
    t : numpy.ndarray, shape (n_samples,)
        Sample times in s, increasing.
    rate : float
        Sampling rate in Hz (of the file, or of the grid after :meth:`resampled`).
    markers : tuple of str
        Marker names, one per column of ``points``.
    events : tuple of (str, float)
        Events the file marks, as (label, time in s), sorted by time.
    source : str
        The file it was read from, named in error messages.
    """

    points: np.ndarray
    t: np.ndarray
    rate: float
    markers: tuple[str, ...]
    events: tuple[tuple[str, float], ...] = ()
    source: str = "<memory>"

    def __post_init__(self) -> None:
        points = np.asarray(self.points, dtype=np.float64)
        t = np.asarray(self.t, dtype=np.float64)
        if points.ndim != 3 or points.shape[2] != 3 or points.shape[1] != len(self.markers):
            raise ValueError(
                f"{self.source}: points must have shape (n_samples, {len(self.markers)}, 3), got {points.shape}"
            )
        if t.shape != (points.shape[0],) or (len(t) > 1 and np.any(np.diff(t) <= 0)):
            raise ValueError(f"{self.source}: t must be {points.shape[0]} increasing times")
        object.__setattr__(self, "points", points)
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "markers", tuple(self.markers))
        object.__setattr__(
            self, "events", tuple(sorted(((str(a), float(b)) for a, b in self.events), key=lambda e: e[1]))
        )

    @property
    def dt(self) -> float:
        """Sampling time in s (``1 / rate``)."""
        return 1.0 / self.rate

    def marker(self, name: str) -> np.ndarray:
        """One marker's positions, shape (n_samples, 3), in mm (NaN where it was not seen)."""
        if name not in self.markers:
            raise ValueError(f"{self.source}: no marker {name!r} (markers: {', '.join(self.markers)})")
        return self.points[:, self.markers.index(name)]

    def gaps(self, name: str) -> np.ndarray:
        """True on the samples where marker ``name`` was not seen."""
        return ~np.isfinite(self.marker(name)).all(axis=1)

    def resampled(self, dt: float = BASE_STEP) -> MarkerRecording:
        """The recording on a regular grid ``t[0] + k dt`` that ends at or before its last sample.

        Each stretch the marker was seen without a break is interpolated by a cubic spline
        (``scipy.interpolate.make_interp_spline``; linear for a stretch of 2-3 samples); a grid time
        outside every stretch, i.e. in a gap or touching one, is NaN: gaps are never bridged.

        Parameters
        ----------
        dt : float
            Grid step in s (> 0); 0.01 is the diagrams' tick.
        """
        if not (isinstance(dt, int | float) and math.isfinite(dt) and dt > 0):
            raise ValueError(f"MarkerRecording.resampled: dt must be a positive number of seconds, got {dt!r}")
        n = int(math.floor((self.t[-1] - self.t[0]) / dt + 1e-9)) + 1
        grid = self.t[0] + dt * np.arange(n)
        return MarkerRecording(self.on_grid(grid), grid, 1.0 / dt, self.markers, self.events, self.source)

    def on_grid(self, grid: np.ndarray) -> np.ndarray:
        """The points at the times ``grid`` (s), interpolated as :meth:`resampled` does: (len(grid), n_markers, 3)."""
        grid = np.asarray(grid, dtype=np.float64)
        tol = 1e-9 * (float(np.median(np.diff(grid))) if len(grid) > 1 else 1.0)
        out = np.full((len(grid), len(self.markers), 3), np.nan)
        for m in range(len(self.markers)):
            seen = np.isfinite(self.points[:, m]).all(axis=1)
            for start, stop in _runs(seen):
                ts, ps = self.t[start:stop], self.points[start:stop, m]
                inside = (grid >= ts[0] - tol) & (grid <= ts[-1] + tol)
                if len(ts) == 1:
                    out[inside, m] = ps[0]
                    continue
                spline = scipy.interpolate.make_interp_spline(ts, ps, k=3 if len(ts) >= 4 else 1, axis=0)
                out[inside, m] = spline(np.clip(grid[inside], ts[0], ts[-1]))
        return out

    def select(self, names: list[str] | tuple[str, ...]) -> MarkerRecording:
        """The recording restricted to the named markers, in that order."""
        columns = [self.markers.index(name) if name in self.markers else None for name in names]
        unknown = [name for name, c in zip(names, columns, strict=True) if c is None]
        if unknown:
            raise ValueError(
                f"{self.source}: no marker(s) {', '.join(map(repr, unknown))} (markers: {', '.join(self.markers)})"
            )
        return MarkerRecording(self.points[:, columns], self.t, self.rate, tuple(names), self.events, self.source)


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) of each run of True in ``mask``."""
    edges = np.diff(np.r_[0, mask.astype(np.int8), 0])
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True))
