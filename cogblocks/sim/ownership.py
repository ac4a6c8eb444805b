"""Which plan runs a diagram's blocks, and private copies for the plans that hand them over.

A diagram's own block objects are run by its latest plan. Compiling a diagram again moves the
earlier plans that still run its blocks onto private deep copies, taken with their current
state, so they continue exactly where they were and independently. A copy duplicates what a
run changes (blocks, ports, declared and undeclared state) and shares what it only reads and
what is costly or impossible to duplicate: torch modules and tensors, casadi objects, and NumPy
arrays that are read-only all the way down (a read-only view of a writeable array can still
change, so it is copied): mark a large table that owns its data read-only with
``table.setflags(write=False)`` to have the copies share it.
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np

__all__ = ["leaf_blocks", "private_copy", "row_copies", "running_plans"]

# objects of these packages are parameters (networks, solvers): shared, never deep-copied
_SHARED_PACKAGES = frozenset({"torch", "casadi"})
# how deep to look inside a block's attributes for shared objects (a wrapper around a network)
_SEARCH_DEPTH = 4


def leaf_blocks(diagram: Any) -> list[Any]:
    """The leaf blocks of ``diagram``, through its sub-diagrams."""
    return [node for node in _nodes(diagram) if not node.composite]


def running_plans(diagram: Any) -> list[Any]:
    """The current plans (not made stale by a change of their diagram) that run blocks of ``diagram``."""
    plans = {id(p): p for b in leaf_blocks(diagram) if (p := b.__dict__.get("_plan")) is not None}
    return [p for p in plans.values() if p.current]


def private_copy(obj: Any, diagram: Any, keep: tuple[Any, ...] = ()) -> Any:
    """Deep-copy ``obj`` (a plan's attributes), which holds ``diagram``, sharing read-only parameters.

    Parameters
    ----------
    obj : object
        What to copy.
    diagram : Diagram
        The diagram ``obj`` runs (it may sit inside a larger diagram; the copy does not).
    keep : tuple
        Objects the copy refers to as they are (the plan itself, its lock).

    Raises
    ------
    TypeError
        Naming the block that cannot be deep-copied.
    """
    memo = _shared(diagram)
    for obj_kept in keep:
        memo[id(obj_kept)] = obj_kept
    try:
        return copy.deepcopy(obj, dict(memo))  # deepcopy fills its memo: keep ours for the search below
    except Exception as exc:  # name the block that holds what cannot be copied
        culprit = next((b for b in leaf_blocks(diagram) if not _copyable(b, memo)), None)
        where = f"block {culprit.name!r} ({type(culprit).__name__})" if culprit is not None else "the diagram"
        raise TypeError(f"{where} cannot be copied ({exc})") from exc


def row_copies(block: Any, diagram: Any, n: int) -> list[Any]:
    """``n`` private deep copies of the leaf ``block`` of ``diagram``, one per run of a batch: they share what
    :func:`private_copy` shares, and their parent is the block's own (the copies are not added to it)."""
    memo = _shared(diagram)
    memo[id(block.parent)] = block.parent
    try:
        return [copy.deepcopy(block, dict(memo)) for _ in range(n)]
    except Exception as exc:
        raise TypeError(f"block {block.name!r} ({type(block).__name__}) cannot be copied for each run ({exc})") from exc


def _shared(diagram: Any) -> dict[int, Any]:
    """A deepcopy memo that leaves out the plans and the diagram around ``diagram`` and shares its parameters."""
    memo: dict[int, Any] = {}
    parent = diagram.parent
    if parent is not None:
        memo[id(parent)] = None
    seen: set[int] = set()
    for node in _nodes(diagram):
        # other plans are not copied along: a diagram's latest plan, the plan that runs a leaf
        for plan in (node.plan if node.composite else None, node.__dict__.get("_plan")):
            if plan is not None:
                memo[id(plan)] = None
        for value in node.__dict__.values():
            _find_shared(value, memo, seen, _SEARCH_DEPTH)
    return memo


def _copyable(block: Any, memo: dict[int, Any]) -> bool:
    alone = dict(memo)
    alone[id(block.parent)] = None  # the block alone, not the diagram around it
    try:
        copy.deepcopy(block, alone)
    except Exception:
        return False
    return True


def _nodes(diagram: Any) -> list[Any]:
    found = [diagram]
    for child in diagram.blocks.values():
        found.extend(_nodes(child) if child.composite else [child])
    return found


def _find_shared(value: Any, memo: dict[int, Any], seen: set[int], depth: int) -> None:
    if id(value) in seen or value is None or isinstance(value, (str, bytes, int, float, complex)):
        return
    seen.add(id(value))
    if type(value).__module__.partition(".")[0] in _SHARED_PACKAGES:
        memo[id(value)] = value
        return
    if isinstance(value, np.ndarray):
        if _read_only(value):
            memo[id(value)] = value
        return
    if depth == 0:
        return
    if isinstance(value, dict):
        children = list(value.values())
    elif isinstance(value, (list, tuple, set, frozenset)):
        children = list(value)
    elif hasattr(value, "__dict__") and not isinstance(value, type):
        children = list(vars(value).values())
    else:
        return
    for child in children:
        _find_shared(child, memo, seen, depth - 1)


def _read_only(arr: Any) -> bool:
    """Whether no writeable array can change ``arr`` (a read-only view of a writeable array can change)."""
    while isinstance(arr, np.ndarray):
        if arr.flags.writeable:
            return False
        arr = arr.base
    return True
