"""Execution order of a compiled diagram, and algebraic loops solved exactly when they are linear.

Blocks run in dependency order over feedthrough wires. A cycle of feedthrough wires (an
algebraic loop) has no such order. When every block on it declares that its outputs are affine
in its feedthrough inputs (:meth:`Block.linear_feedthrough`: ``y = c + D u``, ``c`` from the
state and the inputs off the loop, ``D`` constant), the loop is one linear system per tick,
``(I - M) y = c``, whose inverse is computed once at compile time; this is what
python-control's ``feedback`` does in closed form. Any other loop, or a singular one, is refused
with the cycle named.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from cogblocks.sim.errors import DiagramError

__all__ = ["LinearLoop", "order_blocks"]

# (I - M) with a larger condition number is treated as singular: the loop has no reliable solution
_MAX_CONDITION = 1e12

Deps = dict[str, list[tuple[str, Any]]]


def order_blocks(
    leaves: dict[str, Any], drivers: dict[Any, Any], ticks: dict[str, int], name: Callable[[Any], str]
) -> tuple[list[str], dict[str, LinearLoop]]:
    """Order the leaf blocks over feedthrough wires; solve linear loops, refuse the others.

    Returns
    -------
    order : list of str
        Block paths in execution order (the blocks of one loop next to each other).
    loops : dict
        The first path of every solved loop, mapped to its :class:`LinearLoop`.
    """
    paths = list(leaves)
    index = {id(b): p for p, b in leaves.items()}
    deps: Deps = {p: [] for p in paths}
    for inp, src in drivers.items():
        if inp.feedthrough:
            deps[index[id(inp.block)]].append((index[id(src.block)], inp))
    rank = {p: i for i, p in enumerate(paths)}
    rep: dict[str, str] = {}
    members: dict[str, list[str]] = {}
    loops: dict[str, LinearLoop] = {}
    for comp in _strongly_connected(paths, deps):
        comp.sort(key=rank.__getitem__)
        head = comp[0]
        members[head] = comp
        for p in comp:
            rep[p] = head
        if len(comp) > 1 or any(src == head for src, _ in deps[head]):
            loops[head] = _linear_loop(comp, leaves, drivers, ticks, deps, name)
    # depth-first over the loops collapsed to one node: the order of the loop-free engine
    outward = {head: [rep[s] for p in comp for s, _ in deps[p] if rep[s] != head] for head, comp in members.items()}
    order: list[str] = []
    placed: set[str] = set()
    for root in paths:
        if rep[root] in placed:
            continue
        stack = [(rep[root], 0)]
        placed.add(rep[root])
        while stack:
            node, i = stack[-1]
            if i < len(outward[node]):
                stack[-1] = (node, i + 1)
                nxt = outward[node][i]
                if nxt not in placed:
                    placed.add(nxt)
                    stack.append((nxt, 0))
            else:
                stack.pop()
                order.extend(members[node])
    return order, loops


def _strongly_connected(paths: list[str], deps: Deps) -> list[list[str]]:
    """Tarjan's strongly connected components, iteratively (diagrams can be deep)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    found: list[list[str]] = []
    for root in paths:
        if root in index:
            continue
        work = [(root, 0)]
        while work:
            node, i = work[-1]
            if i == 0:
                index[node] = low[node] = len(index)
                stack.append(node)
                on_stack.add(node)
            if i < len(deps[node]):
                work[-1] = (node, i + 1)
                nxt = deps[node][i][0]
                if nxt not in index:
                    work.append((nxt, 0))
                elif nxt in on_stack:
                    low[node] = min(low[node], index[nxt])
                continue
            work.pop()
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[node])
            if low[node] == index[node]:
                comp = []
                while True:
                    p = stack.pop()
                    on_stack.discard(p)
                    comp.append(p)
                    if p == node:
                        break
                found.append(comp)
    return found


def _describe_cycle(
    comp: list[str], deps: Deps, name: Callable[[Any], str], drivers: dict[Any, Any]
) -> tuple[str, list[Any]]:
    """One cycle through the loop's blocks, in signal-flow order (``a.y -> b.u, b.y -> a.u``), and its inputs."""
    inside = set(comp)
    stack = [comp[0]]
    seen = {comp[0]}
    hops: list[Any] = []  # hops[i]: the input of stack[i] that is fed by stack[i + 1]
    while True:
        node = stack[-1]
        edge = next(((s, inp) for s, inp in deps[node] if s in inside and (s not in seen or s in stack)), None)
        if edge is None:  # dead end inside the component: back up
            stack.pop()
            hops.pop()
            continue
        src, inp = edge
        hops.append(inp)
        if src in stack:
            cycle_inputs = hops[stack.index(src) :]
            break
        seen.add(src)
        stack.append(src)
    text = [f"{name(drivers[inp])} -> {name(inp)}" for inp in reversed(cycle_inputs)]
    return ", ".join(text), cycle_inputs


def _feedthrough_hint(inputs: list[Any], name: Callable[[Any], str]) -> str:
    """The loop's inputs, newest block first: one that only ``update`` reads breaks the loop when declared so."""
    newest = sorted(inputs, key=lambda inp: getattr(inp.block, "_created", -1), reverse=True)
    listed = ", ".join(f"{name(inp)} ({type(inp.block).__name__})" for inp in newest)
    return (
        f"If a block reads one of the loop's inputs only in update(), declare that input with "
        f"add_input(..., feedthrough=False): {listed} (newest block first)"
    )


def _linear_loop(comp, leaves, drivers, ticks, deps, name) -> LinearLoop:
    cycle, inputs = _describe_cycle(comp, deps, name, drivers)
    nonlinear = [p for p in comp if leaves[p].linear_feedthrough() is None]
    if nonlinear:
        p = nonlinear[0]
        raise DiagramError(
            f"algebraic loop: {cycle} (every block on it feeds its input straight to its output, and "
            f"{p} ({type(leaves[p]).__name__}) is not linear; only loops of linear feedthrough blocks such as "
            f"Gain, Sum and DiscreteLTI are solved). {_feedthrough_hint(inputs, name)}; "
            "otherwise break it with a UnitDelay"
        )
    periods = {ticks[p] for p in comp}
    if len(periods) > 1:
        raise DiagramError(f"algebraic loop: {cycle} joins blocks of different periods; give them one period")
    return LinearLoop([leaves[p] for p in comp], drivers, ticks[comp[0]], cycle, name)


class LinearLoop:
    """One algebraic loop of linear feedthrough blocks, solved at each of its ticks.

    Each block's outputs are computed with the loop's wires at zero, which gives the part
    ``c`` that does not go round the loop; the outputs are then ``(I - M)^-1 c``, where ``M``
    holds the blocks' direct-feedthrough matrices placed by the wires.

    Attributes
    ----------
    blocks : list of Block
        The loop's blocks.
    every : int
        Base ticks between two runs of the loop's blocks.
    cycle : str
        A cycle of the loop, for messages.
    """

    def __init__(self, blocks: list[Any], drivers: dict[Any, Any], every: int, cycle: str, name) -> None:
        self.every = every
        self.cycle = cycle
        self.blocks = blocks
        inside = {id(b) for b in blocks}
        slots: dict[int, slice] = {}
        # (array, where) pairs, not views: a plan handed over to a copy deep-copies them, and views would detach
        arrays: list[tuple[np.ndarray, slice]] = []
        n = 0
        for block in blocks:
            for port in block._outputs.values():
                if port.value.dtype.kind != "f":
                    raise DiagramError(f"algebraic loop: {cycle}: {name(port)} is not a float signal")
                slots[id(port)] = slice(n, n + port.value.size)
                arrays.append((port.value, slots[id(port)]))
                n += port.value.size
        loop_gain = np.zeros((n, n))
        self._steps = []
        for block in blocks:
            on_loop = [
                inp
                for inp in block._inputs.values()
                if inp.feedthrough and inp in drivers and id(drivers[inp].block) in inside
            ]
            for (out_name, in_name), d in block.linear_feedthrough().items():
                inp, out = block._inputs[in_name], block._outputs[out_name]
                d = np.asarray(d, dtype=float)
                if d.shape != (out.value.size, inp.value.size):
                    raise DiagramError(
                        f"{name(out)}: linear_feedthrough gives a {d.shape} matrix for input {in_name!r}, "
                        f"expected {(out.value.size, inp.value.size)}"
                    )
                if inp in on_loop:
                    loop_gain[slots[id(out)], slots[id(drivers[inp])]] += d
            own = [(port.value, slots[id(port)]) for port in block._outputs.values()]
            self._steps.append(([inp.value for inp in on_loop], block.output, own))
        system = np.eye(n) - loop_gain
        condition = np.linalg.cond(system)
        if not np.isfinite(condition) or condition > _MAX_CONDITION:
            raise DiagramError(
                f"algebraic loop: {cycle} is singular (I minus its loop gain is not invertible, condition number "
                f"{condition:.3g}): it has no unique solution; break it with a UnitDelay"
            )
        self._solve = np.linalg.inv(system)
        self._arrays = arrays
        self._c = np.zeros(n)

    def output(self, k: int) -> None:
        """Compute every output of the loop's blocks for tick ``k``."""
        c = self._c
        for loop_inputs, output, own in self._steps:
            for arr in loop_inputs:
                arr[...] = 0.0
            output(k)
            for arr, where in own:
                c[where] = arr.ravel()
        y = self._solve @ c
        for arr, where in self._arrays:
            arr[...] = y[where].reshape(arr.shape)
