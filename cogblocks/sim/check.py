"""Checking that a block declares its whole state: a snapshot restored mid-run continues bit for bit.

A block's state is what :meth:`Block.add_state` declares: it is what a snapshot saves and a reset
restores. A block that keeps state in an ordinary attribute (``self.count += 1`` without
``add_state``) runs correctly from the start, but a restored snapshot, a reset or a saved run
continues from the wrong place. :func:`check_block` runs a block alone, takes a snapshot mid-run,
runs on, restores the snapshot and compares the continuation with an uninterrupted run; it names
every attribute that changed between ticks without being declared.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from cogblocks.sim.block import Block
from cogblocks.sim.diagram import Diagram
from cogblocks.sim.errors import SimulationError
from cogblocks.sim.ports import Input, Output
from cogblocks.sim.signal import Signal
from cogblocks.sim.timing import BASE_STEP

__all__ = ["StateCheck", "UndeclaredStateError", "check_block"]

# what the engine keeps on every block; not the block's own state
_ENGINE = frozenset(
    {
        "_inputs",
        "_outputs",
        "_state_init",
        "_scratch",
        "name",
        "period",
        "dt",
        "every",
        "_init_call",
        "_plan",
    }
)
# objects of these packages are parameters (networks, solvers): not compared
_PARAMETER_PACKAGES = frozenset({"torch", "casadi"})
_DEPTH = 4  # how deep to compare inside an attribute's objects


class UndeclaredStateError(SimulationError):
    """A block keeps state outside its declared state: a restored snapshot does not continue the run."""


@dataclass(frozen=True)
class StateCheck:
    """What :func:`check_block` found.

    Attributes
    ----------
    block : str
        The block's class name.
    snapshot_at : int
        The tick the snapshot was taken before.
    n_steps : int
        Ticks run.
    undeclared : tuple of str
        Attributes that changed between ticks without being declared with ``add_state``.
    mismatch : str or None
        The first output of the continuation from the restored snapshot that differs from the
        uninterrupted run, or None when every output agrees bit for bit.
    """

    block: str
    snapshot_at: int
    n_steps: int
    undeclared: tuple[str, ...]
    mismatch: str | None

    @property
    def ok(self) -> bool:
        """True when the block's whole state is declared and the continuation is exact."""
        return not self.undeclared and self.mismatch is None

    def message(self) -> str:
        """A sentence saying what is wrong (empty when :attr:`ok`)."""
        parts = []
        if self.undeclared:
            parts.append(
                f"{self.block} keeps state in undeclared attribute(s) {list(self.undeclared)}: they changed between "
                f"tick {self.snapshot_at} and tick {self.n_steps} and a restored snapshot does not bring them back; "
                "declare them with self.add_state(name, initial value) in __init__"
            )
        if self.mismatch is not None:
            parts.append(f"after restoring the snapshot of tick {self.snapshot_at}, {self.mismatch}")
        return "; ".join(parts)


def check_block(
    block: Block,
    inputs: Mapping[str, Any] | None = None,
    *,
    n_steps: int = 30,
    snapshot_at: int | None = None,
    dt: float = BASE_STEP,
    specs: Mapping[str, Signal] | None = None,
    raise_error: bool = True,
) -> StateCheck:
    """Check that ``block`` declares its whole state: a snapshot restored mid-run continues bit for bit.

    The block is run alone on copies (``block`` itself is not changed): once uninterrupted for
    ``n_steps`` ticks; once to ``snapshot_at``, where its plan's snapshot is taken, on to
    ``n_steps`` (which moves any undeclared state on), then restored to the snapshot and run to
    ``n_steps`` again. Every output of the continuation must equal the uninterrupted run's, bit
    for bit, and no attribute outside the declared state may differ between tick
    ``snapshot_at`` and tick ``n_steps``.

    Parameters
    ----------
    block : Block
        A block, as built (it may sit in a diagram; the check runs a copy alone). For a
        diagram, every block inside is checked; attributes are named by their dotted path.
    inputs : mapping, optional
        Per input, its values tick by tick: an array whose first axis has ``n_steps`` entries,
        or one value for every tick. Inputs with a default may be left out.
    n_steps : int
        Ticks to run (>= 2).
    snapshot_at : int, optional
        The tick the snapshot is taken before (``1 <= snapshot_at < n_steps``; default a third).
    dt : float
        Base step in seconds.
    specs : mapping, optional
        Specs to expose inputs with, where the block's own spec leaves fields open (by default
        shape and dtype come from the values, unit ``"1"``, not wrapped).
    raise_error : bool
        Raise :class:`UndeclaredStateError` when the check fails (default); else return the report.

    Returns
    -------
    StateCheck

    Raises
    ------
    UndeclaredStateError
        Naming the undeclared attributes and the first output that differs.
    ValueError
        For an unknown input, or ticks out of range.

    Examples
    --------
    >>> from cogblocks.blocks import Integrator
    >>> check_block(Integrator(), {"u": 1.0}).ok
    True
    """
    if not (isinstance(n_steps, int) and n_steps >= 2):
        raise ValueError(f"check_block: n_steps must be an integer >= 2, got {n_steps!r}")
    at = max(n_steps // 3, 1) if snapshot_at is None else snapshot_at
    if not (isinstance(at, int) and 1 <= at < n_steps):
        raise ValueError(f"check_block: snapshot_at must be an integer in [1, {n_steps}), got {snapshot_at!r}")
    feeds = _feeds(block, dict(inputs or {}), n_steps, dict(specs or {}))
    reference = _plan(block, feeds, dt)
    expected = [_run(reference, feeds, k) for k in range(n_steps)]
    plan = _plan(block, feeds, dt)
    for k in range(at):
        _run(plan, feeds, k)
    snapshot = plan.state_dict()
    before = _undeclared(plan.blocks)
    for k in range(at, n_steps):
        _run(plan, feeds, k)
    after = _undeclared(plan.blocks)
    changed = tuple(sorted(n for n in before.keys() | after.keys() if not _same(before.get(n), after.get(n), _DEPTH)))
    plan.load_state_dict(snapshot)
    mismatch = None
    for k in range(at, n_steps):
        got = _run(plan, feeds, k)
        mismatch = mismatch or _differs(expected[k], got, k)
    report = StateCheck(type(block).__name__, at, n_steps, changed, mismatch)
    if raise_error and not report.ok:
        raise UndeclaredStateError(report.message())
    return report


def _feeds(block: Block, inputs: dict[str, Any], n: int, specs: dict[str, Signal]) -> dict[str, tuple[Signal, list]]:
    unknown = sorted((set(inputs) | set(specs)) - set(block.inputs))
    if unknown:
        raise ValueError(f"check_block: {type(block).__name__} has no input(s) {unknown}; it has {list(block.inputs)}")
    feeds = {}
    for name, values in inputs.items():
        arr = np.asarray(values)
        port_shape = block.inputs[name].spec.shape
        per_tick = arr.ndim > 0 and arr.shape[0] == n and (port_shape is None or arr.shape[1:] == tuple(port_shape))
        ticks = [arr[k] for k in range(n)] if per_tick else [arr] * n
        feeds[name] = (specs.get(name) or _spec(block.inputs[name], ticks[0]), ticks)
    return feeds


def _spec(port: Input, sample: np.ndarray) -> Signal:
    """The input's spec with its open fields filled from the values it is fed."""
    s = port.spec
    return Signal(
        shape=s.shape if s.shape is not None else sample.shape,
        dtype=s.dtype if s.dtype is not None else sample.dtype,
        unit=s.unit if s.unit is not None else "1",
        wrapped=s.wrapped if s.wrapped is not None else False,
    )


def _plan(block: Block, feeds: Mapping[str, tuple[Signal, list]], dt: float) -> Any:
    memo: dict[int, Any] = {id(block.parent): None}
    nodes = [block, *block.walk()] if block.composite else [block]
    for node in nodes:  # other plans are not copied; parameters are shared, as plans share them
        for plan in (node.plan if node.composite else None, node.__dict__.get("_plan")):
            memo[id(plan)] = None
        for value in vars(node).values():
            if type(value).__module__.partition(".")[0] in _PARAMETER_PACKAGES:
                memo[id(value)] = value
    clone = copy.deepcopy(block, memo)
    d = Diagram()
    d.add("block", clone)
    for name, (spec, _) in feeds.items():
        d.expose_input(name, clone.inputs[name], spec=spec)
    for name, port in clone.outputs.items():
        d.expose_output(name, port)
    return d.compile(dt)


def _run(plan: Any, feeds: Mapping[str, tuple[Signal, list]], k: int) -> dict[str, np.ndarray]:
    out = plan.step(**{name: ticks[k] for name, (_, ticks) in feeds.items()})
    return {name: np.array(value, copy=True) for name, value in out.items()}


def _differs(expected: Mapping[str, np.ndarray], got: Mapping[str, np.ndarray], k: int) -> str | None:
    for name, want in expected.items():
        have = got[name]
        if want.dtype != have.dtype or not np.array_equal(want, have, equal_nan=want.dtype.kind in "fc"):
            return f"output {name!r} at tick {k} is {have.tolist()!r}, the uninterrupted run gave {want.tolist()!r}"
    return None


def _undeclared(leaves: Mapping[str, Block]) -> dict[str, Any]:
    """Copies of the leaves' attributes outside the declared state, scratch and ports, by ``path.name``.

    A block checked alone is the path ``block``; its attributes are named without it.
    """
    found = {}
    for path, block in leaves.items():
        prefix = "" if path == "block" else f"{path.removeprefix('block.')}."
        found.update({prefix + name: value for name, value in _attributes(block).items()})
    return found


def _attributes(block: Block) -> dict[str, Any]:
    found = {}
    for name, value in vars(block).items():
        if name in _ENGINE or name in block.state_names or name in block.scratch_names:
            continue
        if isinstance(value, (Input, Output)) or value is block.parent:
            continue
        if type(value).__module__.partition(".")[0] in _PARAMETER_PACKAGES:
            continue
        try:
            found[name] = copy.deepcopy(value)
        except Exception:  # not copyable (a handle, a lock): not comparable either
            continue
    return found


def _same(a: Any, b: Any, depth: int) -> bool:
    """Whether two attribute values are equal, NaN equal to NaN, looking ``depth`` levels into objects."""
    if type(a) is not type(b):
        return False
    if isinstance(a, np.ndarray):
        if a.shape != b.shape or a.dtype != b.dtype:
            return False
        if a.dtype.kind == "O":
            return all(_same(x, y, depth - 1) for x, y in zip(a.flat, b.flat, strict=True))
        return bool(np.array_equal(a, b, equal_nan=a.dtype.kind in "fc"))
    if isinstance(a, np.random.Generator):
        return _same(a.bit_generator.state, b.bit_generator.state, depth)
    if isinstance(a, float):
        return a == b or (math.isnan(a) and math.isnan(b))
    if isinstance(a, (bool, int, str, bytes, complex, type(None), np.generic)):
        return bool(a == b) or (isinstance(a, np.floating) and bool(np.isnan(a) and np.isnan(b)))
    if type(a).__module__.partition(".")[0] in _PARAMETER_PACKAGES or depth <= 0:
        return True
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k], depth - 1) for k in a)
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y, depth - 1) for x, y in zip(a, b, strict=True))
    if isinstance(a, (set, frozenset)):
        return a == b
    if hasattr(a, "__dict__") and not callable(a):
        return _same(vars(a), vars(b), depth - 1)
    return True
