"""The compiled plan: a flattened, ordered, pre-bound diagram that runs tick by tick."""

from __future__ import annotations

import difflib
import math
import os
import threading
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from cogblocks.sim.batch import allocate, batch_size, bind, warn_per_row
from cogblocks.sim.block import Block
from cogblocks.sim.errors import DiagramError, SimulationError
from cogblocks.sim.loops import order_blocks
from cogblocks.sim.ownership import leaf_blocks, private_copy, running_plans
from cogblocks.sim.ports import Input, Output
from cogblocks.sim.snapshot import check_snapshot, load_snapshot, save_snapshot
from cogblocks.sim.specs import check_driven, resolve_specs
from cogblocks.sim.timing import BASE_STEP

if TYPE_CHECKING:
    from cogblocks.sim.diagram import Diagram

__all__ = ["CompiledDiagram"]

# Above this many distinct tick phases the per-phase schedule is built on demand.
_MAX_PHASES = 4096


class CompiledDiagram:
    """A diagram validated, flattened and ordered for running.

    Built by :meth:`Diagram.compile`. Every signal lives in one preallocated
    array shared by the output that writes it and the inputs that read it, and
    the per-tick work is a precomputed list of bound methods, so a tick does no
    graph work and no dictionary look-ups.

    A plan owns the blocks it runs. The latest plan of a diagram runs the
    diagram's own blocks; compiling the diagram again moves the earlier plans
    onto private copies of their blocks, with their state (see
    :mod:`cogblocks.sim.ownership`), so plans of one diagram never share state.
    A plan goes stale when its diagram changes (``add``, ``connect``,
    ``expose_*``, ``replace``) and then refuses to run.

    A plan is not thread-safe: run it from one thread at a time. Running it from
    a second thread while a step or run is in progress raises
    :class:`SimulationError` instead of silently losing ticks.

    Attributes
    ----------
    dt : float
        Base step in seconds.
    k : int
        Index of the next tick to run.
    batch : int or None
        Runs at once (``compile(dt, batch=B)``, :mod:`cogblocks.sim.batch`), or None: no batch axis.
    blocks : dict
        Leaf blocks by dotted path, in execution order.
    diagram : Diagram
        The diagram the plan runs: ``source`` itself, or its private copy once
        a later plan took over ``source``'s blocks.
    source : Diagram
        The diagram that was compiled.
    """

    def __init__(self, diagram: Diagram, dt: float = BASE_STEP, *, batch: int | None = None) -> None:
        if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
            raise DiagramError(f"the base step dt must be a positive number of seconds, got {dt!r}")
        for plan in running_plans(diagram):
            plan._hand_over()  # the earlier plan continues on a copy; this one takes the blocks
        self.source = self.diagram = diagram
        self._revision = diagram.revision
        self._stale_reason: str | None = None
        self._lock = threading.Lock()
        self.dt = float(dt)
        self.batch = batch_size(batch)
        self.k = 0
        leaves: dict[str, Block] = {}
        periods: dict[str, float | None] = {}
        drivers: dict[Input, Output] = {}
        external: dict[str, list[Input]] = {}
        self._flatten(diagram, "", None, leaves, periods, drivers, external)
        self._ext_outputs = {name: self._leaf_output(diagram, name) for name in diagram.exposed_outputs}
        self._paths = {id(b): p for p, b in leaves.items()}
        check_driven(leaves, drivers, external, self._name)
        resolve_specs(diagram, leaves, drivers, external, self._ext_outputs, self._name)
        ticks = self._periods(leaves, periods)
        self._rows = allocate(leaves, ticks, self.dt, self.batch, diagram)
        self._external = bind(diagram, leaves, drivers, external, self.batch, self._rows, self._name)
        order, self._loops = order_blocks(leaves, drivers, ticks, self._name)
        if self._loops and self.batch is not None:
            raise DiagramError(
                f"the algebraic loops through {sorted(self._loops)} cannot run batched yet; compile unbatched"
            )
        self.blocks = {p: leaves[p] for p in order}
        self._runs = {p: self._rows.get(p, b) for p, b in self.blocks.items()}  # what runs each path
        self._ticks = [ticks[p] for p in order]
        self._build_schedule()
        run = [*self.blocks.values(), *(c for r in self._rows.values() for c in r.copies)]
        self._output_arrays = [(port, port.value) for b in run for port in b._outputs.values()]
        for block in leaf_blocks(diagram):
            object.__setattr__(block, "_plan", self)
        self.reset()
        warn_per_row(self._rows)

    @property
    def per_row(self) -> tuple[str, ...]:
        """Paths of the blocks that run one copy per run of the batch (blocks that are not ``batchable``)."""
        return tuple(self._rows)

    @property
    def current(self) -> bool:
        """False once the compiled diagram has changed: the plan then refuses to run; compile again."""
        return self.source.revision == self._revision

    def _hand_over(self) -> None:
        """Continue on a private copy of the blocks, state included: a new plan takes the diagram's blocks."""
        if not self._lock.acquire(blocking=False):
            raise SimulationError(
                "cannot compile this diagram while an earlier plan of it is running (in another thread)"
            )
        try:
            keep = (self, self._lock) if self.diagram is self.source else (self, self._lock, self.source)
            moved = private_copy(dict(self.__dict__), self.diagram, keep)
        except TypeError as exc:  # a block that cannot be copied: this plan ends here, and says why
            self._revision = -1
            self._stale_reason = (
                f"a later compile of its diagram took over its blocks, and {exc}, so this plan could not "
                "continue on a copy; use the later plan, or build one diagram per plan"
            )
        else:
            moved["source"] = self.source
            moved["_paths"] = {id(b): p for p, b in moved["blocks"].items()}
            self.__dict__.update(moved)
            for rows in self._rows.values():  # the copied row views are arrays of their own: view the rows again
                rows.bind()
        finally:
            self._lock.release()

    def _enter(self) -> None:
        """Take the plan for one step or run: refuse a stale plan and concurrent use."""
        if self.source.revision != self._revision:
            raise SimulationError(
                self._stale_reason
                or "the diagram changed (a block added, replaced or rewired) after this plan was compiled, so "
                "the plan no longer runs it; compile it again (diagram.compile() or a new Simulator)"
            )
        if not self._lock.acquire(blocking=False):
            raise SimulationError(
                "this compiled diagram is already running (in another thread, or re-entered from a block); "
                "a plan is not thread-safe: step it from one thread at a time, or compile one plan per thread"
            )

    # -- flattening ----------------------------------------------------------
    def _flatten(self, d, prefix, period, leaves, periods, drivers, external) -> None:
        own_period = d.period if d.period is not None else period
        for name, child in d.blocks.items():
            path = prefix + name
            if child.composite:
                self._flatten(child, path + ".", own_period, leaves, periods, drivers, external)
            else:
                leaves[path] = child
                periods[path] = child.period if child.period is not None else own_period
        children = d.blocks
        for (s_child, s_port), (d_child, d_port) in d.wires:
            src = self._leaf_output(children[s_child], s_port)
            for dst in self._leaf_inputs(children[d_child], d_port):
                drivers[dst] = src
        if not prefix:
            for name in d.exposed_inputs:
                external[name] = self._leaf_inputs(d, name)

    def _leaf_output(self, block: Block, port: str) -> Output:
        while block.composite:
            child, port = block.exposed_outputs[port]
            block = block.blocks[child]
        return block.outputs[port]

    def _leaf_inputs(self, block: Block, port: str) -> list[Input]:
        if not block.composite:
            return [block.inputs[port]]
        found: list[Input] = []
        for child, child_port in block.exposed_inputs[port]:
            found.extend(self._leaf_inputs(block.blocks[child], child_port))
        return found

    def _name(self, port: Input | Output) -> str:
        block = port.block
        path = self._paths.get(id(block)) or next(p for p, r in self._rows.items() if block in r.copies)
        return f"{path}.{port.name}"

    # -- validation ----------------------------------------------------------
    def _periods(self, leaves, periods) -> dict[str, int]:
        ticks: dict[str, int] = {}
        for path, period in periods.items():
            if period is None:
                ticks[path] = 1
                continue
            n = round(period / self.dt) if period > 0 else 0
            if not (
                isinstance(period, (int, float))
                and period > 0
                and n >= 1
                and abs(n * self.dt - period) <= 1e-9 * max(1.0, period)
            ):
                raise DiagramError(
                    f"block {path!r} asks for a period of {period!r} s, which is not a positive multiple of the "
                    f"base step {self.dt} s; use k * {self.dt} for an integer k >= 1"
                )
            ticks[path] = n
        return ticks

    # -- schedule ------------------------------------------------------------
    def _build_schedule(self) -> None:
        on_loops = {id(b) for loop in self._loops.values() for b in loop.blocks}
        self._outs_all = []
        for n, (path, b) in zip(self._ticks, self.blocks.items(), strict=True):
            if path in self._loops:  # a loop's blocks are computed together, by its solver
                self._outs_all.append((n, self._loops[path].output))
            elif id(b) not in on_loops and type(b).output is not Block.output:
                # blocks that only hold a value (Constant) or are only read (Probe) need no call
                self._outs_all.append((n, self._runs[path].output))
        self._upds_all = [(n, r.update) for n, r in zip(self._ticks, self._runs.values(), strict=True) if r.stateful]
        hyper = 1
        for n in set(self._ticks):
            hyper = hyper * n // math.gcd(hyper, n)
        self._hyper = hyper
        self._phases: list[tuple[tuple[Callable, ...], tuple[Callable, ...]]] | None = None
        if hyper <= _MAX_PHASES:
            self._phases = [self._phase(k) for k in range(hyper)]

    def _phase(self, k: int) -> tuple[tuple[Callable, ...], tuple[Callable, ...]]:
        return (
            tuple(f for n, f in self._outs_all if k % n == 0),
            tuple(f for n, f in self._upds_all if k % n == 0),
        )

    def _tick_functions(self):
        """Per-tick (outputs, updates) lookup: a table, or a function for huge hyperperiods."""
        if self._phases is not None:
            phases, hyper = self._phases, self._hyper
            return lambda k: phases[k % hyper]
        return self._phase

    # -- running -------------------------------------------------------------
    @property
    def time(self) -> float:
        """Time of the next tick, in seconds."""
        return self.k * self.dt

    @property
    def input_names(self) -> tuple[str, ...]:
        """Names of the top-level diagram inputs that :meth:`step` and runs feed."""
        return tuple(self._external)

    @property
    def output_names(self) -> tuple[str, ...]:
        """Names of the top-level diagram outputs that :meth:`step` returns."""
        return tuple(self._ext_outputs)

    def set_inputs(self, **inputs: Any) -> None:
        """Write the top-level diagram inputs for the next tick."""
        self._check_input_names(inputs)
        for name, value in inputs.items():
            arr = self._external[name]
            given = np.asarray(value)
            if given.shape != arr.shape:
                # no silent broadcasting: a scalar for a vector is almost always a wiring mistake
                raise ValueError(f"input {name!r} expects shape {arr.shape}, got {given.shape}")
            if arr.dtype.kind in "iub" and given.dtype.kind not in "iub":
                if given.dtype.kind not in "f" or not np.all(np.isfinite(given)) or np.any(given != np.round(given)):
                    raise ValueError(f"input {name!r} expects {arr.dtype} values, got {value!r}")
                info = np.iinfo(arr.dtype) if arr.dtype.kind in "iu" else None
                if info is not None and (np.any(given < info.min) or np.any(given > info.max)):
                    raise ValueError(f"input {name!r} expects {arr.dtype} values, got {value!r} (out of range)")
            try:
                arr[...] = given
            except (ValueError, TypeError) as exc:
                raise ValueError(
                    f"input {name!r} expects {arr.dtype} values of shape {arr.shape}, got {value!r}"
                ) from exc

    def _check_input_names(self, inputs: Mapping[str, Any]) -> None:
        for name in inputs:
            if name not in self._external:
                close = difflib.get_close_matches(name, self._external, n=1, cutoff=0.5)
                hint = f" (did you mean {close[0]!r}?)" if close else ""
                raise KeyError(
                    f"the diagram has no input {name!r}{hint}; its inputs are {list(self._external)}"
                    + ("" if self._external else " (expose one with Diagram.expose_input)")
                )

    def step(self, **inputs: Any) -> dict[str, Any]:
        """Run one tick with the given top-level inputs; return the top-level outputs.

        Inputs not given keep their previous value. Outputs are copies: scalars as
        ``float``, vectors as arrays. This is the call to make inside a live loop.
        """
        self._enter()
        try:
            self._check_input_names(inputs)
            k = self.k
            if k == 0:
                missing = [n for n in self._external if n not in inputs]
                if missing:
                    raise ValueError(f"the first step needs every diagram input; missing {missing}")
            self.set_inputs(**inputs)
            outs, upds = self._tick_functions()(k)
            for f in outs:
                f(k)
            result = {
                name: (port.value.item() if port.value.ndim == 0 else port.value.copy())
                for name, port in self._ext_outputs.items()
            }
            for f in upds:
                f(k)
            self.k = k + 1
            if k == 0:
                self._check_outputs_in_place()
            return result
        finally:
            self._lock.release()

    def _check_outputs_in_place(self) -> None:
        for port, arr in self._output_arrays:
            if port.value is not arr:
                raise SimulationError(
                    f"block {self._name(port)[: -len(port.name) - 1]!r} replaced the array of its output "
                    f"{port.name!r} instead of writing into it; write with port.value[...] = x"
                )

    def advance(
        self,
        n_steps: int,
        record: Callable[[int], None] | None = None,
        feed: Callable[[int], None] | None = None,
    ) -> None:
        """Run ``n_steps`` ticks; ``feed(k)`` writes inputs before, ``record(k)`` reads after the outputs."""
        self._enter()
        try:
            tick = self._tick_functions()
            k = self.k
            end = k + n_steps
            if k == 0 and n_steps > 0:
                self._run_ticks(tick, 0, 1, record, feed)
                self._check_outputs_in_place()
                k = 1
            self._run_ticks(tick, k, end, record, feed)
        finally:
            self._lock.release()

    def _run_ticks(self, tick, k: int, end: int, record, feed) -> None:
        # The hot loop: kept free of attribute look-ups and allocation.
        try:
            if record is None and feed is None:
                while k < end:
                    outs, upds = tick(k)
                    for f in outs:
                        f(k)
                    for f in upds:
                        f(k)
                    k += 1
            else:
                while k < end:
                    if feed is not None:
                        feed(k)
                    outs, upds = tick(k)
                    for f in outs:
                        f(k)
                    if record is not None:
                        record(k)
                    for f in upds:
                        f(k)
                    k += 1
        finally:
            self.k = k

    def reset(self) -> None:
        """Restore every block to its initial state and rewind to tick 0."""
        self._enter()
        try:
            for block in self._runs.values():
                block.reset()
            for arr in self._external.values():
                arr[...] = 0
            self.k = 0
        finally:
            self._lock.release()

    def state_dict(self) -> dict[str, Any]:
        """Snapshot: the tick counter, every block's state and outputs, the diagram inputs."""
        return {
            "k": self.k,
            "blocks": {path: block.state_dict() for path, block in self._runs.items()},
            "inputs": {name: arr.copy() for name, arr in self._external.items()},
        }

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """Restore a snapshot taken with :meth:`state_dict` on the same diagram.

        Every block path, state entry, output and input is checked (names, array
        shapes and dtypes) before anything changes: a snapshot that does not fit
        raises ``ValueError`` naming the block and the entry, and leaves the plan
        as it was.
        """
        check_snapshot(self._runs, self._external, state)
        self._enter()
        try:
            for path, block_state in state["blocks"].items():
                self._runs[path].load_state_dict(block_state)
            for name, value in state["inputs"].items():
                self._external[name][...] = value
            self.k = int(state["k"])
        finally:
            self._lock.release()

    def save_state(self, path: str | os.PathLike) -> None:
        """Write :meth:`state_dict` to the ``.npz`` file ``path`` (no pickle; see :mod:`cogblocks.sim.snapshot`)."""
        save_snapshot(self.state_dict(), path)

    def load_state(self, path: str | os.PathLike) -> None:
        """Load a snapshot written by :meth:`save_state`, checked like :meth:`load_state_dict`."""
        self.load_state_dict(load_snapshot(path))

    # -- looking things up ---------------------------------------------------
    def output_port(self, path: str) -> Output:
        """The leaf output behind ``"block.port"`` (dotted through sub-diagrams), or a top-level output's name."""
        if path in self._ext_outputs:
            return self._ext_outputs[path]
        block_path, _, port = path.rpartition(".")
        try:
            block = self.diagram[block_path] if block_path else None
        except KeyError:
            block = None
        if block is None or port not in block._outputs:
            raise KeyError(f"{path!r} is not an output port of the diagram")
        return self._leaf_output(block, port)

    def path_of(self, block: Block) -> str:
        """The dotted path of a leaf block."""
        return self._paths[id(block)]
