"""Batches: one compiled plan running B independent runs of a diagram at once.

``diagram.compile(dt, batch=B)`` gives every signal a leading batch axis: an output of shape
``shape`` becomes an array of shape ``(B, *shape)``, row ``b`` belonging to run ``b``. A block
whose class sets ``batchable = True`` runs all rows in one call: its ``output`` and ``update``
read and write the batched arrays, and it sizes its state in :meth:`Block.setup` from
:attr:`Block.batch_shape` (``()`` unbatched, ``(B,)`` batched), so one code path serves both
and an unbatched compile is exactly what it always was. Any other block runs *per row*: the
plan makes one private copy of it per run (:class:`RowCopies`), each bound to its row of the
batched signals, so it still works in a batch, only at B times the calls; the plan names those
blocks in :attr:`CompiledDiagram.per_row` and warns once with a :class:`PerRowWarning`.

Rows never mix: a batched block computes each row from that row alone, so bad data in one run
(NaN) stays in that run.
"""

from __future__ import annotations

import numbers
import warnings
from collections.abc import Mapping
from typing import Any

import numpy as np

from cogblocks.sim.errors import DiagramError
from cogblocks.sim.ownership import row_copies

__all__ = ["PerRowWarning", "RowCopies", "allocate", "batch_size", "bind", "warn_per_row"]

#: Separates the run's index from the state's name in a per-row block's snapshot entries.
_ROW = "/"


class PerRowWarning(UserWarning):
    """A block in a batched plan cannot run the batch at once and runs one copy per row (slower, same results)."""


def batch_size(batch: Any) -> int | None:
    """``batch`` checked: ``None`` (no batch axis) or a number of runs >= 1."""
    if batch is None:
        return None
    if isinstance(batch, bool) or not isinstance(batch, numbers.Integral) or batch < 1:
        raise ValueError(f"batch must be None or a number of runs >= 1, got {batch!r}")
    return int(batch)


class RowCopies:
    """The runs of a block that cannot batch: one private copy per row, each bound to its row of the batch.

    The block in the diagram keeps the batched arrays on its ports (what probes and lookups read) and
    is not run itself; :attr:`copies` run, copy ``b`` on row ``b``.
    """

    def __init__(self, block: Any, batch: int, diagram: Any) -> None:
        self.block = block
        self.copies = row_copies(block, diagram, batch)
        for b, copy in enumerate(self.copies):
            copy.batch = None
            for name, port in copy._outputs.items():
                port.value = block._outputs[name].value[b, ...]  # a view, 0-d for a scalar signal
            copy.setup()
        self.stateful = block.stateful
        self._outs = [copy.output for copy in self.copies]
        self._upds = [copy.update for copy in self.copies]

    def bind(self) -> None:
        """Point each copy's ports at its row of the block's arrays (the inputs bound by :func:`bind`).

        Called again after a deep copy of the plan, which copies each row view as an array of its own.
        """
        for b, copy in enumerate(self.copies):
            for name, port in copy._outputs.items():
                port.value = self.block._outputs[name].value[b, ...]
            for name, port in copy._inputs.items():
                given = self.block._inputs[name]
                port.value, port.driven = given.value[b, ...], given.driven

    def output(self, k: int) -> None:
        for f in self._outs:
            f(k)

    def update(self, k: int) -> None:
        for f in self._upds:
            f(k)

    def reset(self) -> None:
        for copy in self.copies:
            copy.reset()

    def state_dict(self) -> dict[str, Any]:
        """Every copy's state under ``"<row>/<name>"``, and the batched outputs."""
        state = {
            f"{b}{_ROW}{name}": value
            for b, c in enumerate(self.copies)
            for name, value in c.state_dict()["state"].items()
        }
        return {"state": state, "outputs": {name: port.value.copy() for name, port in self.block._outputs.items()}}

    def _rows(self, state: Any) -> list[dict[str, Any]]:
        rows: list[dict[str, Any]] = [{"state": {}, "outputs": {}} for _ in self.copies]
        for key, value in state["state"].items():
            row, _, name = str(key).partition(_ROW)
            if not row.isdigit() or int(row) >= len(rows):
                raise KeyError(key)
            rows[int(row)]["state"][name] = value
        for name, value in state["outputs"].items():
            for b, row in enumerate(rows):
                row["outputs"][name] = np.asarray(value)[b, ...] if np.ndim(value) else value
        return rows

    def _state_dict_problem(self, state: Any) -> str | None:
        try:
            rows = self._rows(state)
        except (KeyError, TypeError, AttributeError, IndexError):
            return f"not a snapshot of a block run per row over {len(self.copies)} runs ('<row>/<state>' entries)"
        for name, port in self.block._outputs.items():
            saved = state["outputs"].get(name)
            if not (isinstance(saved, np.ndarray) and saved.shape == port.value.shape):
                return f"output {name!r} expects an array of shape {port.value.shape}"
        for b, (copy, row) in enumerate(zip(self.copies, rows, strict=True)):
            problem = copy._state_dict_problem(row)
            if problem:
                return f"run {b}: {problem}"
        return None

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        for copy, row in zip(self.copies, self._rows(state), strict=True):
            copy.load_state_dict(row)


def allocate(leaves: dict[str, Any], ticks: dict[str, int], dt: float, batch: int | None, diagram: Any) -> dict:
    """Give every leaf its step and output arrays, with the batch axis, and set it up; returns the per-row blocks."""
    lead = () if batch is None else (batch,)
    rows: dict[str, RowCopies] = {}
    for path, block in leaves.items():
        block.dt = ticks[path] * dt
        block.every = ticks[path]
        whole = batch is None or bool(block.batchable)
        block.batch = batch if whole else None
        for port in block._outputs.values():
            port.value = np.zeros(lead + port.spec.shape, dtype=port.spec.dtype)
        if whole:
            block.setup()
        else:
            rows[path] = RowCopies(block, batch, diagram)
    return rows


def bind(
    diagram: Any, leaves: dict[str, Any], drivers: dict, external: dict, batch: int | None, rows: dict, name: Any
) -> dict[str, np.ndarray]:
    """Bind every input to the array that drives it (an output, a diagram input, its default); returns the
    diagram inputs' arrays. Defaults get the batch axis; a block's default may hold one row per run."""
    lead = () if batch is None else (batch,)
    arrays: dict[str, np.ndarray] = {}
    fed = {id(inp) for targets in external.values() for inp in targets}
    for key, targets in external.items():
        spec = targets[0].spec.merge(diagram._inputs[key].spec)
        arr = np.zeros(lead + spec.shape, dtype=spec.dtype)
        arrays[key] = arr
        for inp in targets:
            inp.value, inp.driven = arr, True
    for block in leaves.values():
        for inp in block._inputs.values():
            if inp in drivers:
                inp.value, inp.driven = drivers[inp].value, True
            elif id(inp) not in fed:
                try:
                    default = np.broadcast_to(inp.default, lead + inp.spec.shape)
                except ValueError:
                    runs = "a batch of " + str(batch) if batch else "no batch"
                    raise DiagramError(
                        f"{name(inp)}: its default of shape {inp.default.shape} does not fit {runs} of signals of "
                        f"shape {inp.spec.shape} (a default with one row per run needs compile(dt, batch=rows))"
                    ) from None
                inp.value, inp.driven = np.array(default, dtype=inp.spec.dtype), False
    for copies in rows.values():
        copies.bind()
    return arrays


def warn_per_row(rows: Mapping[str, RowCopies]) -> None:
    """Say which blocks of a batched plan run per row."""
    if rows:
        kinds = ", ".join(f"{path!r} ({type(r.block).__name__})" for path, r in rows.items())
        warnings.warn(
            f"these blocks cannot run a batch at once and run one copy per run: {kinds}; the results are the same, "
            "the time is that of separate runs (CompiledDiagram.per_row lists them)",
            PerRowWarning,
            stacklevel=4,
        )
