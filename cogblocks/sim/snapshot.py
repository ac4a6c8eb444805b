"""Snapshots of a compiled diagram: checking one before it is loaded, and saving it to an ``.npz`` file.

A snapshot is what :meth:`CompiledDiagram.state_dict` returns: the tick ``k``, per block path its
declared ``state`` and its ``outputs``, and the top-level diagram ``inputs``. The file format is a
NumPy ``.npz`` archive without pickle: arrays as arrays, everything else (numbers, random
generator states, small lists) in a JSON manifest, so a snapshot reloads bit for bit.
"""

from __future__ import annotations

import json
import numbers
import os
from collections.abc import Mapping
from typing import Any

import numpy as np

__all__ = ["check_snapshot", "generators", "load_snapshot", "save_snapshot", "value_problem"]

_FORMAT = "cogblocks-snapshot"
_VERSION = 1


def generators(value: Any) -> bool:
    """Whether ``value`` is a list of random generators (one per run of a batch), snapshotted by their states."""
    return isinstance(value, list) and bool(value) and all(isinstance(g, np.random.Generator) for g in value)


def value_problem(current: Any, initial: Any, saved: Any) -> str | None:
    """What is wrong with ``saved`` as the new value of a state now ``current`` (declared as ``initial``).

    Arrays of a fixed layout (declared and current alike) must keep their shape and dtype;
    numbers stay numbers; a random generator takes only a state of its own kind of bit
    generator. Other state is free-form and accepted as it is.
    """
    if isinstance(current, np.random.Generator):
        kind = current.bit_generator.state["bit_generator"]
        if not (isinstance(saved, Mapping) and saved.get("bit_generator") == kind):
            return f"expects the state of a {kind} random generator, got {_describe(saved)}"
        return None
    if generators(current):
        kinds = [g.bit_generator.state["bit_generator"] for g in current]
        if not (isinstance(saved, list) and len(saved) == len(current)) or any(
            not (isinstance(s, Mapping) and s.get("bit_generator") == kind)
            for s, kind in zip(saved, kinds, strict=True)
        ):
            return f"expects the states of {len(current)} {kinds[0]} random generators, got {_describe(saved)}"
        return None
    if isinstance(current, np.ndarray):
        fixed = isinstance(initial, np.ndarray) and (initial.shape, initial.dtype) == (current.shape, current.dtype)
        if fixed and not (
            isinstance(saved, np.ndarray) and saved.shape == current.shape and saved.dtype == current.dtype
        ):
            return f"expects an array of shape {current.shape} and dtype {current.dtype}, got {_describe(saved)}"
        return None
    if isinstance(current, numbers.Number) and isinstance(initial, numbers.Number):
        if not isinstance(saved, numbers.Number):
            return f"expects a number, got {_describe(saved)}"
    return None


def _describe(value: Any) -> str:
    if isinstance(value, np.ndarray):
        return f"an array of shape {value.shape} and dtype {value.dtype}"
    return f"{type(value).__name__} {value!r}"[:120]


def check_snapshot(blocks: Mapping[str, Any], inputs: Mapping[str, np.ndarray], state: Any) -> None:
    """Raise ``ValueError`` naming the first block and entry of ``state`` that does not fit; change nothing.

    Parameters
    ----------
    blocks : mapping
        The plan's leaf blocks by path.
    inputs : mapping
        The plan's top-level input arrays by name.
    state : mapping
        The snapshot to check.
    """
    if not isinstance(state, Mapping) or not {"k", "blocks"} <= set(state):
        raise ValueError(f"not a snapshot of a compiled diagram (a mapping with 'k' and 'blocks'): {_describe(state)}")
    k = state["k"]
    if isinstance(k, bool) or not isinstance(k, numbers.Integral) or k < 0:
        raise ValueError(f"snapshot: the tick k must be a non-negative integer, got {k!r}")
    saved_blocks = state["blocks"]
    if not isinstance(saved_blocks, Mapping) or set(saved_blocks) != set(blocks):
        names = sorted(saved_blocks) if isinstance(saved_blocks, Mapping) else []
        only_saved = sorted(set(names) - set(blocks))
        only_here = sorted(set(blocks) - set(names))
        raise ValueError(
            f"state dict is for blocks {names}, this diagram has {sorted(blocks)} (a snapshot of another "
            f"diagram: only in the snapshot {only_saved}, only in this diagram {only_here}); nothing was loaded"
        )
    for path, block in blocks.items():
        problem = block._state_dict_problem(saved_blocks[path])
        if problem:
            raise ValueError(
                f"snapshot does not fit block {path!r} ({type(block).__name__}): {problem}; nothing was loaded"
            )
    saved_inputs = state.get("inputs", {})
    if not isinstance(saved_inputs, Mapping) or set(saved_inputs) != set(inputs):
        raise ValueError(
            f"snapshot has diagram inputs {sorted(saved_inputs) if isinstance(saved_inputs, Mapping) else None}, "
            f"this diagram has {sorted(inputs)}; nothing was loaded"
        )
    for name, arr in inputs.items():
        problem = value_problem(arr, arr, saved_inputs[name])
        if problem:
            raise ValueError(f"snapshot does not fit the diagram input {name!r}: {problem}; nothing was loaded")


def save_snapshot(state: Mapping[str, Any], path: str | os.PathLike) -> None:
    """Write ``state`` (a :meth:`CompiledDiagram.state_dict`) to the ``.npz`` file ``path``, exactly as named."""
    arrays: dict[str, np.ndarray] = {}
    entries: list[list[Any]] = []  # [where..., how, payload]

    def put(where: list[str], value: Any) -> None:
        if isinstance(value, np.ndarray) and not value.dtype.hasobject:
            key = f"a{len(arrays)}"
            arrays[key] = value
            entries.append([*where, "array", key])
        elif isinstance(value, np.generic) and not isinstance(value, np.object_):
            key = f"a{len(arrays)}"
            arrays[key] = np.asarray(value)
            entries.append([*where, "scalar", key])
        else:
            try:
                json.dumps(value, allow_nan=True)
            except (TypeError, ValueError):
                raise ValueError(
                    f"snapshot entry {'.'.join(where)} is a {type(value).__name__}, which cannot be saved without "
                    "pickle (arrays, numbers, random generator states and lists or dicts of numbers can)"
                ) from None
            entries.append([*where, "tuple" if isinstance(value, tuple) else "json", value])

    for path_, block_state in state["blocks"].items():
        for part in ("state", "outputs"):
            for name, value in block_state[part].items():
                put(["blocks", path_, part, name], value)
    for name, value in state.get("inputs", {}).items():
        put(["inputs", name], value)
    manifest = {
        "format": _FORMAT,
        "version": _VERSION,
        "k": int(state["k"]),
        "blocks": list(state["blocks"]),
        "entries": entries,
    }
    with open(path, "wb") as f:
        np.savez(f, __manifest__=np.array(json.dumps(manifest, allow_nan=True)), **arrays)


def load_snapshot(path: str | os.PathLike) -> dict[str, Any]:
    """Read a snapshot written by :func:`save_snapshot` (no pickle is ever loaded)."""
    from cogblocks.sim.reading import open_npz, parse_json

    with open_npz(path, "cogblocks snapshot") as f:
        if "__manifest__" not in f.files:
            raise ValueError(f"{os.fspath(path)!r} is not a cogblocks snapshot (no manifest)")
        manifest = parse_json(str(f["__manifest__"]), path, "snapshot's manifest")
        if not isinstance(manifest, dict) or manifest.get("format") != _FORMAT or manifest.get("version") != _VERSION:
            raise ValueError(f"{os.fspath(path)!r} is not a version {_VERSION} cogblocks snapshot")
        blocks = {path_: {"state": {}, "outputs": {}} for path_ in manifest["blocks"]}
        state: dict[str, Any] = {"k": manifest["k"], "blocks": blocks, "inputs": {}}
        for *where, how, payload in manifest["entries"]:
            if how == "array":
                value = f[payload]
            elif how == "scalar":
                value = f[payload][()]
            else:
                value = tuple(payload) if how == "tuple" else payload
            if where[0] == "blocks":
                _, path_, part, name = where
                blocks[path_][part][name] = value
            else:
                state["inputs"][where[1]] = value
    return state
