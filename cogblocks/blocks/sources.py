"""Sources: blocks whose output does not depend on any input (a constant, a recorded signal)."""

from __future__ import annotations

from typing import Any

import numpy as np

from cogblocks.sim import Block, SimulationError
from cogblocks.sim.params import (
    finite_array,
    one_of,
)

__all__ = ["Constant", "Playback"]


class Constant(Block):
    """Output a constant value.

    Ports: output ``y`` (shape of ``value``).

    Parameters
    ----------
    value : array_like
        The value: finite numbers (a float64 signal), or bools or ints (kept as they are).
    unit : str
        Unit of the output.
    wrapped : bool
        Whether the value is an angle wrapped to one turn.

    Notes
    -----
    Bad data policy: no inputs; a non-finite value is refused when built.
    """

    batchable = True  # the same value in every run

    def __init__(self, value: Any, *, unit: str = "1", wrapped: bool = False, period: float | None = None) -> None:
        super().__init__(period=period)
        given = np.asarray(value)
        # flags and counters stay what they are; everything else is a float signal
        dtype = given.dtype if given.dtype.kind in "bi" else np.float64
        arr = given if dtype != np.float64 else finite_array(self, "value", value)
        self.add_output("y", shape=arr.shape, dtype=dtype, unit=unit, wrapped=wrapped, initial=arr)


class Playback(Block):
    """Play an array, one row per step of the block.

    Ports: output ``y`` (shape of one row).

    Parameters
    ----------
    data : array_like
        Samples, shape ``(n, *shape)``; with ``per_run``, ``(n, B, *shape)``: one recording per run of a batch.
    unit, wrapped : signal spec of the output.
    at_end : {"hold", "repeat", "zero", "error"}
        What to output after the last row.
    per_run : bool
        Whether ``data``'s second axis holds the runs of a batch (``compile(dt, batch=B)``); without it
        every run plays the same samples.

    Notes
    -----
    Bad data policy: NaN rows are played as they are; Playback is how bad data
    gets into a diagram on purpose.
    """

    def __init__(
        self,
        data: Any,
        *,
        unit: str = "1",
        wrapped: bool = False,
        at_end: str = "hold",
        per_run: bool = False,
        period: float | None = None,
    ) -> None:
        super().__init__(period=period)
        if not isinstance(per_run, (bool, np.bool_)):
            raise ValueError(f"Playback: per_run must be True or False, got {per_run!r}")
        arr = np.array(data, dtype=np.float64)
        if arr.ndim < 1 + bool(per_run) or len(arr) == 0:
            raise ValueError(f"Playback: data must be an array with at least one row, got shape {arr.shape}")
        if np.isinf(arr).any():
            raise ValueError("Playback: data must not contain inf (NaN is allowed, to model missing samples)")
        self.data = arr
        self.at_end = one_of(self, "at_end", at_end, ("hold", "repeat", "zero", "error"))
        self.per_run = bool(per_run)
        self.add_output("y", shape=arr.shape[2:] if per_run else arr.shape[1:], unit=unit, wrapped=wrapped)

    batchable = True  # every run plays its own row (per_run) or the same samples

    def setup(self) -> None:
        if self.per_run and self.batch != self.data.shape[1]:
            raise self._fail(f"data holds {self.data.shape[1]} runs (per_run); compile with batch={self.data.shape[1]}")

    def output(self, k: int) -> None:
        i = k // self.every
        n = len(self.data)
        if i >= n:
            if self.at_end == "hold":
                i = n - 1
            elif self.at_end == "repeat":
                i %= n
            elif self.at_end == "zero":
                self.y.value[...] = 0.0
                return
            else:
                raise SimulationError(f"{self.name}: played all {n} samples; at_end='error'")
        self.y.value[...] = self.data[i]
