"""The library projector: nearest non-fear and fear library movements of the buffered window."""

from __future__ import annotations

from typing import Any

import numpy as np

from cogblocks.blocks.samples import PLAUSIBLE, plausible
from cogblocks.blocks.specs import COUNT, VELOCITY
from cogblocks.data.reach import ReachLibrary
from cogblocks.sim import Block, Signal
from cogblocks.sim.params import one_of, positive_int

__all__ = ["LibraryProjector", "PrefixProjection"]


class PrefixProjection:
    """Running distances between a growing prefix and the same prefix of every library movement.

    ``accumulate`` adds the contribution of new samples to per-movement running sums, so bringing the
    projection up to date costs O(library size × new samples), whatever the elapsed time. Per sample
    the contribution is the Euclidean distance ``‖x(t) − v_d(t)‖`` (``metric="mean"``: the mean
    Euclidean distance over the window, as in the notes and the prototype) or its square
    (``metric="l2"``: the paper's ``dist``, squared). Past the library's length a library movement is
    at rest (zero velocity).

    Parameters
    ----------
    velocity : numpy.ndarray, shape (n, T, 3)
        The library's padded velocities.
    metric : {"mean", "l2"}
    dtype : {"float32", "float64"}
        Precision of the stored library and of the per-sample distances; the running sums are
        float64. ``float32`` halves the memory and is about four times faster on large libraries.
    block : int
        Samples processed per vectorised step (the size of the preallocated work array).
    """

    def __init__(self, velocity: np.ndarray, *, metric: str = "mean", dtype: str = "float32", block: int = 10) -> None:
        self.metric = one_of("PrefixProjection", "metric", metric, ("mean", "l2"))
        dtype = one_of("PrefixProjection", "dtype", dtype, ("float32", "float64"))
        velocity = np.asarray(velocity)
        if velocity.ndim != 3 or velocity.shape[2] != 3:
            raise ValueError(f"PrefixProjection: velocity must have shape (n, T, 3), got {velocity.shape}")
        # time-major (T, 3, n): the rows of one sample are contiguous across the library
        self._library = np.ascontiguousarray(np.transpose(velocity, (1, 2, 0)), dtype=dtype)
        self.size = velocity.shape[0]
        self.max_len = velocity.shape[1]
        self._block = positive_int("PrefixProjection", "block", block)
        self._diff = np.empty((self._block, 3, self.size), dtype=dtype)
        self._dist = np.empty((self._block, self.size), dtype=dtype)

    def accumulate(self, sums: np.ndarray, samples: np.ndarray, start: int) -> None:
        """Add the samples numbered ``start, start + 1, …`` (shape (m, 3)) to ``sums`` (n,) in place."""
        samples = np.asarray(samples)
        for offset in range(0, len(samples), self._block):
            part = samples[offset : offset + self._block]
            t0 = start + offset
            inside = max(0, min(len(part), self.max_len - t0))
            if inside:
                diff, dist = self._diff[:inside], self._dist[:inside]
                np.subtract(self._library[t0 : t0 + inside], part[:inside, :, None], out=diff)
                np.multiply(diff, diff, out=diff)
                np.sum(diff, axis=1, out=dist)
                if self.metric == "mean":
                    np.sqrt(dist, out=dist)
                sums += dist.sum(axis=0, dtype=np.float64)
            if inside < len(part):
                rest = np.einsum("ij,ij->i", part[inside:], part[inside:])
                sums += float(np.sqrt(rest).sum() if self.metric == "mean" else rest.sum())

    def distance(self, sums: np.ndarray, count: int) -> np.ndarray:
        """The distances the sums stand for after ``count`` samples: mean Euclidean, or the L² norm."""
        return sums / max(count, 1) if self.metric == "mean" else np.sqrt(sums)


class LibraryProjector(Block):
    """Online projection of the buffered human movement onto the library's prefixes (section III-B).

    Every ``interval`` samples (when the buffer's ``count`` reaches a multiple of it) the buffered
    prefix is compared with the same prefix of every library movement: the nearest movement of the
    set that does not encode ``e_des`` is η_i, and after the first window the nearest movement of
    the set that does is chosen, once, as the reference ``v_r``. Decisions are taken in the update
    phase, so the decision on samples ``0 … T_i − 1`` shows from tick ``T_i`` on: the first
    ``interval`` ticks have no decision (the blender passes the human signal through).

    The distances are kept as running sums (:class:`PrefixProjection`), so a decision costs
    O(library size × ``interval``).

    Ports
    -----
    velocity : input, shape (capacity, 3), mm/s
        The velocity ring of a :class:`~cogblocks.amplification.Buffer` (read in the update phase).
    count : input, int64
        Samples received by the buffer (read in the update phase).
    nearest : output, int64
        Library index of η_i; −1 before the first decision.
    reference : output, int64
        Library index of the reference movement; −1 before the first decision.
    v_r : output, shape (3,), mm/s
        The reference's velocity at this tick (zero before the reference is chosen and after its end).
    decisions : output, int64
        Decisions taken so far.
    horizon : output, int64
        The expected end of the altered movement in samples, ``max(length(η_i), length(v_r))``; 0
        before the first decision.

    Parameters
    ----------
    library : ReachLibrary
        The movement library, with its fear labels.
    e_des : {0, 1}
        1: the reference encodes fear (η among the no-fear movements); 0: the roles swap.
    interval : int
        ΔT, samples between two decisions (10).
    metric, dtype : see :class:`PrefixProjection`.
    candidates : array_like of bool, shape (n,), optional
        Library movements the projection may choose (all by default), for instance to leave the
        replayed movement itself out.

    Notes
    -----
    The samples of a decision must still be in the buffer: ``interval`` may not exceed its
    capacity.

    Bad data policy: the buffer upstream replaces non-finite and implausible samples; fed
    directly, an element beyond 1 km/s (:func:`~cogblocks.blocks.samples.plausible`, NaN
    included) counts as that bound with its sign, so the distances stay finite and the decision
    follows the other samples.
    """

    def __init__(
        self,
        library: ReachLibrary,
        *,
        e_des: int = 1,
        interval: int = 10,
        metric: str = "mean",
        dtype: str = "float32",
        candidates: Any = None,
        period: float | None = None,
    ) -> None:
        super().__init__(period=period)
        if not isinstance(library, ReachLibrary):
            raise ValueError(f"LibraryProjector: library must be a ReachLibrary, got {type(library).__name__}")
        self.e_des = one_of(self, "e_des", e_des, (0, 1))
        self.interval = positive_int(self, "interval", interval)
        allowed = np.ones(len(library), dtype=bool) if candidates is None else np.asarray(candidates, dtype=bool)
        if allowed.shape != (len(library),):
            raise ValueError(f"LibraryProjector: candidates must have shape ({len(library)},), got {allowed.shape}")
        self._nearest_set = np.flatnonzero((library.fear != bool(self.e_des)) & allowed)
        self._reference_set = np.flatnonzero((library.fear == bool(self.e_des)) & allowed)
        if self._nearest_set.size == 0 or self._reference_set.size == 0:
            raise ValueError("LibraryProjector: the library needs candidate movements with and without the emotion")
        self.library = library
        self.add_scratch("projection", None)  # the library's layout and the distance work buffers
        self.projection = PrefixProjection(library.velocity, metric=metric, dtype=dtype, block=self.interval)
        self.add_input("velocity", Signal(shape=None, unit="mm/s"), feedthrough=False)
        self.add_input("count", COUNT, feedthrough=False)
        self.add_output("nearest", COUNT, initial=-1)
        self.add_output("reference", COUNT, initial=-1)
        self.add_output("v_r", VELOCITY)
        self.add_output("decisions", COUNT)
        self.add_output("horizon", COUNT)
        self.add_state("sums", np.zeros(len(library)))
        self.add_state("seen", 0)
        self.add_state("n_decisions", 0)
        self.add_state("eta", -1)
        self.add_state("ref", -1)

    def setup(self) -> None:
        shape = self.velocity.spec.shape
        if len(shape) != 2 or shape[1] != 3:
            raise self._fail(f"velocity must have shape (capacity, 3), got {shape}")
        if self.interval > shape[0]:
            raise self._fail(f"interval {self.interval} exceeds the buffer's capacity {shape[0]}")

    def output(self, k: int) -> None:
        t = k // self.every
        self.nearest.value[...] = self.eta
        self.reference.value[...] = self.ref
        self.decisions.value[...] = self.n_decisions
        if self.ref >= 0 and t < self.library.max_len:
            self.v_r.value[...] = self.library.velocity[self.ref, t]
        else:
            self.v_r.value[...] = 0.0
        lengths = self.library.length
        self.horizon.value[...] = max(lengths[self.eta], lengths[self.ref]) if self.eta >= 0 else 0

    def update(self, k: int) -> None:
        count = int(self.count.value)
        if count // self.interval <= self.n_decisions:
            return
        ring = self.velocity.value
        if count - self.seen > len(ring):
            raise self._fail(f"samples {self.seen}…{count - 1} no longer fit the buffer of {len(ring)}")
        rows = np.arange(self.seen, count) % len(ring)
        samples = ring[rows]
        if not plausible(samples):
            samples = np.clip(np.nan_to_num(samples, nan=0.0), -PLAUSIBLE, PLAUSIBLE)
        self.projection.accumulate(self.sums, samples, self.seen)
        self.seen = count
        self.eta = int(self._nearest_set[np.argmin(self.sums[self._nearest_set])])
        if self.ref < 0:
            self.ref = int(self._reference_set[np.argmin(self.sums[self._reference_set])])
        self.n_decisions = count // self.interval
