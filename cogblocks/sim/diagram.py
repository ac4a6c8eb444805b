"""Diagrams: blocks wired together; a diagram with exposed ports is itself a block."""

from __future__ import annotations

import os
import re
import warnings
from collections.abc import Iterator, Mapping
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

from cogblocks.sim.block import Block
from cogblocks.sim.errors import DiagramError
from cogblocks.sim.graph import PortEnd, Wire
from cogblocks.sim.ports import Input, Output
from cogblocks.sim.signal import ANY, Signal
from cogblocks.sim.timing import BASE_STEP

if TYPE_CHECKING:
    from cogblocks.sim.compiled import CompiledDiagram

__all__ = ["Diagram", "PortEnd", "Wire"]

PortRef = Input | Output | str
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


class Diagram(Block):
    """A set of named blocks and the wires between them.

    A diagram is itself a :class:`~cogblocks.sim.Block`: ports exposed with
    :meth:`expose_input` and :meth:`expose_output` are its ports, so a whole
    architecture can be one block inside a larger diagram and be swapped as a
    unit. Compiling flattens the hierarchy, so a nested diagram runs exactly like
    its flattened equivalent.

    Parameters
    ----------
    period : float, optional
        Default period for the blocks inside that do not set their own.

    Examples
    --------
    >>> from cogblocks.blocks import Constant, Integrator, Probe
    >>> d = Diagram()
    >>> c = d.add("c", Constant(2.0))
    >>> x = d.add("x", Integrator())
    >>> d.connect(c.y, x.u)
    >>> _ = d.add("px", Probe()); d.connect(x.y, "px.u")
    >>> from cogblocks.sim import Simulator
    >>> round(float(Simulator(d).run(n_steps=101)["px"][-1]), 9)  # 100 steps of 2 * 0.01
    2.0
    """

    composite = True

    def __init__(self, *, period: float | None = None) -> None:
        super().__init__(period=period)
        self._children: dict[str, Block] = {}
        # wires between direct children: (src child, src port) -> [(dst child, dst port)]
        self._wires: list[tuple[str, str, str, str]] = []
        self._exposed_in: dict[str, list[tuple[str, str]]] = {}
        self._exposed_out: dict[str, tuple[str, str]] = {}
        self._compiled: CompiledDiagram | None = None
        # bumped by every change, here or in a sub-diagram: plans compiled before it are stale
        self._revision = 0

    def _changed(self) -> None:
        """Note a change of this diagram: its plans and its ancestors' plans go stale."""
        node: Diagram | None = self
        while node is not None:
            node._revision += 1
            node._compiled = None
            node = getattr(node, "_parent", None)

    # -- building ------------------------------------------------------------
    def add(self, name: str, block: Block, *, period: float | None = None) -> Block:
        """Add ``block`` under ``name`` and return it.

        ``period`` (seconds), if given, sets the block's period.
        """
        if not isinstance(name, str) or not _NAME.match(name):
            raise DiagramError(f"block names must be identifiers, got {name!r}")
        if not isinstance(block, Block):
            raise DiagramError(f"can only add Block instances, got {type(block).__name__} for {name!r}")
        if "_inputs" not in block.__dict__:
            raise DiagramError(f"{type(block).__name__} was not initialised: its __init__ must call super().__init__()")
        if name in self._children:
            raise DiagramError(f"the diagram already has a block named {name!r}")
        if block is self or (isinstance(block, Diagram) and self in block.walk()):
            raise DiagramError(f"adding {name!r} would make the diagram contain itself")
        for other_name, other in self._children.items():
            if other is block:
                raise DiagramError(f"this block instance is already in the diagram as {other_name!r}")
        if block.name is not None and getattr(block, "_parent", None) is not None:
            raise DiagramError(f"block {block.name!r} already belongs to another diagram; create a new instance")
        if period is not None:
            block.period = period
        block.name = name
        object.__setattr__(block, "_parent", self)
        self._children[name] = block
        self._changed()
        return block

    def walk(self) -> Iterator[Block]:
        """Every block inside, depth first: each child, then (for a sub-diagram) the blocks inside it."""
        for child in self._children.values():
            yield child
            if isinstance(child, Diagram):
                yield from child.walk()

    @property
    def blocks(self) -> Mapping[str, Block]:
        """The direct children by name (a copy: adding to it does not change the diagram)."""
        return dict(self._children)

    @property
    def wires(self) -> tuple[Wire, ...]:
        """The wires between direct children, in the order they were connected."""
        return tuple(Wire(PortEnd(s, sp), PortEnd(d, dp)) for s, sp, d, dp in self._wires)

    @property
    def exposed_inputs(self) -> Mapping[str, tuple[PortEnd, ...]]:
        """Each input of this diagram and the children's inputs it feeds (read-only)."""
        return MappingProxyType({n: tuple(PortEnd(c, p) for c, p in t) for n, t in self._exposed_in.items()})

    @property
    def exposed_outputs(self) -> Mapping[str, PortEnd]:
        """Each output of this diagram and the child's output it carries (read-only)."""
        return MappingProxyType({n: PortEnd(c, p) for n, (c, p) in self._exposed_out.items()})

    @property
    def revision(self) -> int:
        """A counter bumped by every change to this diagram or a sub-diagram: plans of an older revision are stale."""
        return self._revision

    @property
    def plan(self) -> CompiledDiagram | None:
        """The plan of the last :meth:`compile`, or None if the diagram was never compiled (or changed since)."""
        return self._compiled

    def __getitem__(self, path: str) -> Block:
        """A child block by name, or a nested one by dotted path (``"l2.blender"``)."""
        node: Block = self
        for part in path.split("."):
            if not isinstance(node, Diagram) or part not in node._children:
                raise KeyError(f"no block {path!r} in the diagram (children: {list(self._children)})")
            node = node._children[part]
        return node

    def __contains__(self, path: str) -> bool:
        try:
            return self[path] is not None
        except KeyError:
            return False

    def _port(self, ref: PortRef, kind: type) -> tuple[str, Any]:
        """Resolve a port reference to (child name, port) for a direct child."""
        if isinstance(ref, str):
            child_name, _, port_name = ref.rpartition(".")
            if not child_name or child_name not in self._children:
                raise DiagramError(
                    f"{ref!r} does not name a port of a block of this diagram (blocks: {list(self._children)})"
                )
            child = self._children[child_name]
            table = child._inputs if kind is Input else child._outputs
            if port_name not in table:
                what = "input" if kind is Input else "output"
                raise DiagramError(
                    f"block {child_name!r} ({type(child).__name__}) has no {what} {port_name!r}; it has {list(table)}"
                )
            return child_name, table[port_name]
        if not isinstance(ref, kind):
            want = "an input" if kind is Input else "an output"
            raise DiagramError(f"expected {want} port, got {ref!r}")
        owner = ref.block
        for child_name, child in self._children.items():
            if child is owner:
                return child_name, ref
        where = f"block {owner.name!r}" if owner.name else f"an unnamed {type(owner).__name__}"
        raise DiagramError(
            f"port {ref.name!r} belongs to {where}, which is not a direct child of this diagram; "
            "add the block first, or expose the port through its sub-diagram"
        )

    def _driver_of(self, child: str, port: str) -> str | None:
        for s_child, s_port, d_child, d_port in self._wires:
            if (d_child, d_port) == (child, port):
                return f"{s_child}.{s_port}"
        for ext, targets in self._exposed_in.items():
            if (child, port) in targets:
                return f"the diagram input {ext!r}"
        return None

    def connect(self, source: PortRef, *targets: PortRef) -> None:
        """Wire an output to one or more inputs.

        Ports are given as objects (``a.y``) or strings (``"a.y"``). The specs are
        checked now, when both are known; an input can be driven only once.
        """
        if not targets:
            raise DiagramError("connect() needs at least one target input")
        s_child, s_port = self._port(source, Output)
        resolved = [self._port(t, Input) for t in targets]
        for d_child, d_port in resolved:
            driver = self._driver_of(d_child, d_port.name)
            if driver is not None:
                raise DiagramError(
                    f"input {d_child}.{d_port.name} is already driven by {driver}; "
                    f"cannot also connect {s_child}.{s_port.name}"
                )
            if s_port.spec is not None:
                _check_specs(f"{s_child}.{s_port.name}", s_port.spec, f"{d_child}.{d_port.name}", d_port.spec)
        for d_child, d_port in resolved:
            self._wires.append((s_child, s_port.name, d_child, d_port.name))
        self._changed()

    def expose_input(self, name: str, *targets: PortRef, spec: Signal | None = None) -> Input:
        """Make ``name`` an input of this diagram, feeding the given child inputs.

        The new port's spec is the merge of the targets' specs (or ``spec``).
        """
        if not targets:
            raise DiagramError(f"expose_input({name!r}) needs at least one target input")
        resolved = [self._port(t, Input) for t in targets]
        merged = spec if spec is not None else ANY
        for d_child, d_port in resolved:
            driver = self._driver_of(d_child, d_port.name)
            if driver is not None:
                raise DiagramError(f"input {d_child}.{d_port.name} is already driven by {driver}")
            problem = merged.mismatch(d_port.spec)
            if problem:
                raise DiagramError(
                    f"diagram input {name!r} ({merged}) cannot feed {d_child}.{d_port.name} ({d_port.spec}): {problem}"
                )
            merged = merged.merge(d_port.spec)
        port = self.add_input(name, merged, feedthrough=True)
        self._exposed_in[name] = [(c, p.name) for c, p in resolved]
        self._changed()
        return port

    def expose_output(self, name: str, source: PortRef) -> Output:
        """Make ``name`` an output of this diagram, carrying a child's output."""
        s_child, s_port = self._port(source, Output)
        self._check_init(name)
        port = Output(self, name, s_port.spec)
        self._outputs[name] = port
        object.__setattr__(self, name, port)
        self._exposed_out[name] = (s_child, s_port.name)
        self._changed()
        return port

    def replace(self, path: str, block: Block) -> Block:
        """Swap the block at ``path`` for ``block``, keeping its wires.

        The new block must have every port of the old one that is wired; ports nobody wired
        (an optional input left at its default, an unread output) may be missing, and a
        warning names them. Returns the block that was replaced.
        """
        parent_path, _, name = path.rpartition(".")
        parent = self[parent_path] if parent_path else self
        if not isinstance(parent, Diagram) or name not in parent._children:
            raise KeyError(f"no block {path!r} to replace")
        old = parent._children[name]
        wired_in = {p for _, _, c, p in parent._wires if c == name}
        wired_in |= {p for targets in parent._exposed_in.values() for c, p in targets if c == name}
        wired_out = {p for c, p, _, _ in parent._wires if c == name}
        wired_out |= {p for c, p in parent._exposed_out.values() if c == name}
        missing = sorted(wired_in - set(block._inputs)) + sorted(wired_out - set(block._outputs))
        if missing:
            raise DiagramError(
                f"cannot replace {path!r}: the new {type(block).__name__} lacks the wired port(s) {missing} "
                f"(the old block has inputs {sorted(old._inputs)} and outputs {sorted(old._outputs)}, "
                f"the new one {sorted(block._inputs)} and {sorted(block._outputs)})"
            )
        dropped = sorted(set(old._inputs) - set(block._inputs)) + sorted(set(old._outputs) - set(block._outputs))
        del parent._children[name]
        object.__setattr__(old, "_parent", None)
        old.name = None
        try:
            parent.add(name, block)
        except DiagramError:
            parent._children[name] = old
            old.name = name
            object.__setattr__(old, "_parent", parent)
            raise
        for s_child, s_port, d_child, d_port in parent._wires:  # the new block's wires meet the same specs
            if name in (s_child, d_child) and (src := parent._children[s_child]._outputs[s_port]).spec is not None:
                dst = parent._children[d_child]._inputs[d_port]
                _check_specs(f"{s_child}.{s_port}", src.spec, f"{d_child}.{d_port}", dst.spec)
        parent._changed()
        if dropped:
            what = f"the new {type(block).__name__} has no port(s) {dropped} of the old {type(old).__name__}"
            warnings.warn(f"replace({path!r}): {what}; nothing was wired to them, so they are dropped", stacklevel=2)
        return old

    # -- compiling and running -----------------------------------------------
    def compile(self, dt: float = BASE_STEP, *, batch: int | None = None) -> CompiledDiagram:
        """Validate, flatten and order the diagram into a runnable plan.

        The new plan runs this diagram's own blocks (the block objects you hold
        show its state, and it becomes :attr:`compiled`); earlier plans of the
        diagram continue on private copies of their blocks, with their state, so
        plans of one diagram are independent. Changing the diagram makes its
        plans stale: they refuse to run.

        Parameters
        ----------
        dt : float
            The base step in seconds (10 ms by default).
        batch : int, optional
            Run that many independent runs at once: every signal gets a leading axis of ``batch`` rows
            (:mod:`cogblocks.sim.batch`). ``None``, the default, has no batch axis.
        """
        from cogblocks.sim.compiled import CompiledDiagram

        self._compiled = CompiledDiagram(self, dt, batch=batch)
        return self._compiled

    @property
    def compiled(self) -> CompiledDiagram:
        """The plan of the last :meth:`compile`.

        Compiling is explicit: without a plan this compiles at :data:`~cogblocks.sim.BASE_STEP`
        with a :class:`DeprecationWarning` (an error in the next release); call :meth:`compile`.
        """
        return self._plan_for("compiled")

    def _plan_for(self, what: str) -> CompiledDiagram:
        """The current plan; without one, compile at the base step and warn that this will be an error."""
        if self._compiled is None:
            message = f"Diagram.{what} on a diagram with no current plan compiles it at the {BASE_STEP} s base step"
            warnings.warn(f"{message}; call diagram.compile(dt) first (this will raise in the next release)",
                          DeprecationWarning, stacklevel=3)  # fmt: skip
            return self.compile()
        return self._compiled

    def step(self, **inputs: Any) -> dict[str, Any]:
        """Run one tick of the plan of the last :meth:`compile`; see :meth:`CompiledDiagram.step`."""
        return self._plan_for("step()").step(**inputs)

    def reset(self) -> None:
        """Reset the compiled plan (every block's state and the tick counter)."""
        if self._compiled is not None:
            self._compiled.reset()
        else:
            for block in self.walk():
                if not isinstance(block, Diagram):
                    block.reset()

    def state_dict(self) -> dict[str, Any]:
        """Snapshot of the whole diagram (every block's state, outputs and the tick)."""
        return self._plan_for("state_dict()").state_dict()

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """Restore a snapshot taken with :meth:`state_dict`."""
        self._plan_for("load_state_dict()").load_state_dict(state)

    def save_state(self, path: str | os.PathLike) -> None:
        """Write the snapshot of :attr:`compiled` to an ``.npz`` file; see :meth:`CompiledDiagram.save_state`."""
        self._plan_for("save_state()").save_state(path)

    def load_state(self, path: str | os.PathLike) -> None:
        """Load a snapshot file into :attr:`compiled`; see :meth:`CompiledDiagram.load_state`."""
        self._plan_for("load_state()").load_state(path)

    # -- looking at it -------------------------------------------------------
    def to_mermaid(self) -> str:
        """The diagram as a Mermaid flowchart (sub-diagrams as subgraphs)."""
        from cogblocks.sim.render import to_mermaid

        return to_mermaid(self)

    def to_dot(self) -> str:
        """The diagram in Graphviz DOT (sub-diagrams as clusters)."""
        from cogblocks.sim.render import to_dot

        return to_dot(self)

    def draw(self, path: str | os.PathLike) -> None:
        """Draw the diagram to a file, by its suffix; see :func:`cogblocks.sim.render.draw`.

        ``.dot``/``.gv`` and ``.mmd`` are always written; ``.svg``, ``.png`` and ``.pdf`` need Graphviz's ``dot``.
        """
        from cogblocks.sim.render import draw

        draw(self, path)

    def __repr__(self) -> str:
        from cogblocks.sim.render import summary

        return summary(self)


def _check_specs(src_name: str, src: Signal, dst_name: str, dst: Signal) -> None:
    problem = src.mismatch(dst)
    if problem:
        raise DiagramError(f"cannot connect {src_name} {src} to {dst_name} {dst}: {problem}")
