"""A fixed-capacity circular buffer of an incoming 3D motion (velocity and position).

The PoP of Amplification compares the part of a movement received so far with a library of
movements (appendix paper, section III-B). :class:`Buffer` keeps the newest ``capacity`` samples in
preallocated ring arrays that are its outputs, so a downstream block reads the samples it has not
seen yet (rows ``j % capacity`` for the sample numbers ``j`` since it last looked) without any copy
of the history being made on the way."""

from __future__ import annotations

import numpy as np

from cogblocks.blocks.samples import PLAUSIBLE, plausible
from cogblocks.blocks.specs import COUNT, POSITION, VELOCITY
from cogblocks.sim import Block, Signal
from cogblocks.sim.params import positive_int

__all__ = ["Buffer", "ordered_window"]


class Buffer(Block):
    """Circular buffer of the last ``capacity`` samples of a velocity and a position.

    Sample number ``j`` (0 for the first tick) is stored in row ``j % capacity`` of the ring
    outputs; once ``capacity`` samples have arrived each new one overwrites the oldest.

    Ports
    -----
    v : input, shape (3,), mm/s
        Velocity sample.
    p : input, shape (3,), mm
        Position sample.
    velocity : output, shape (capacity, 3), mm/s
        The velocity ring (rows not written yet are zero).
    position : output, shape (capacity, 3), mm
        The position ring.
    count : output, int64
        Samples received so far, this tick's included: the newest sample is in row
        ``(count - 1) % capacity``.
    length : output, int64
        Valid rows, ``min(count, capacity)``.

    Parameters
    ----------
    capacity : int
        Number of samples kept (200 by default: the padded length of the movement library).

    Notes
    -----
    Bad data policy: a sample with a non-finite or implausible element (beyond 1 km or 1 km/s,
    :func:`~cogblocks.blocks.samples.plausible`) is stored as the last good one (zeros before
    any), so that sample numbers keep following the clock. It runs a batch at once, this run by run
    (the runs of a batch receive their samples on the same ticks, so they share ``received``).
    """

    batchable = True

    def __init__(self, capacity: int = 200, *, period: float | None = None) -> None:
        super().__init__(period=period)
        self.capacity = positive_int(self, "capacity", capacity)
        ring_v = Signal(shape=(self.capacity, 3), unit="mm/s")
        ring_p = Signal(shape=(self.capacity, 3), unit="mm")
        self.add_input("v", VELOCITY)
        self.add_input("p", POSITION)
        self.add_output("velocity", ring_v)
        self.add_output("position", ring_p)
        self.add_output("count", COUNT)
        self.add_output("length", COUNT)
        # The rings live in the outputs, which the engine snapshots, restores and resets with the
        # state; writing one row per tick is what keeps the buffer O(1) per sample.
        self.add_state("received", 0)
        self.add_state("last_v", np.zeros(3))
        self.add_state("last_p", np.zeros(3))

    def setup(self) -> None:
        self.add_state("last_v", np.zeros(self.batch_shape + (3,)))
        self.add_state("last_p", np.zeros(self.batch_shape + (3,)))

    def output(self, k: int) -> None:
        row = self.received % self.capacity
        v, p = self.v.value, self.p.value
        if self.batch is not None:
            for given, last, ring in ((v, self.last_v, self.velocity.value), (p, self.last_p, self.position.value)):
                good = np.all(np.abs(given) < PLAUSIBLE, axis=-1, keepdims=True)
                ring[:, row] = np.where(good, given, last)
            self.count.value[...] = self.received + 1
            self.length.value[...] = min(self.received + 1, self.capacity)
            return
        self.velocity.value[row] = v if plausible(v) else self.last_v
        self.position.value[row] = p if plausible(p) else self.last_p
        self.count.value[...] = self.received + 1
        self.length.value[...] = min(self.received + 1, self.capacity)

    def update(self, k: int) -> None:
        row = self.received % self.capacity
        self.last_v[...] = self.velocity.value[..., row, :]
        self.last_p[...] = self.position.value[..., row, :]
        self.received += 1


def ordered_window(ring: np.ndarray, count: int) -> np.ndarray:
    """The buffered samples of a ring in time order, oldest first (a copy).

    Parameters
    ----------
    ring : numpy.ndarray, shape (capacity, ...)
        A ring output of :class:`Buffer`.
    count : int
        Samples received so far (the buffer's ``count`` output).

    Returns
    -------
    numpy.ndarray, shape (min(count, capacity), ...)
    """
    capacity = len(ring)
    if count <= capacity:
        return ring[:count].copy()
    start = count % capacity
    return np.concatenate([ring[start:], ring[:start]])
