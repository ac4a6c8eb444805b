"""Checks of constructor parameters, with messages that name the parameter, the value and what is allowed."""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import numpy as np

from cogblocks.sim.block import Block

__all__ = [
    "block_with_ports",
    "finite_array",
    "finite_number",
    "flag",
    "one_of",
    "positive_int",
    "random_generator",
    "shape_arg",
    "unit_arg",
    "wrapped_arg",
]


def _owner(owner: object) -> str:
    return owner if isinstance(owner, str) else type(owner).__name__


def finite_number(
    owner: object,
    name: str,
    value: Any,
    *,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = False,
    high_open: bool = False,
) -> float:
    """Return ``value`` as a float, or raise ``ValueError`` if it is not finite or out of range."""
    lo = "(" if low_open or low is None else "["
    hi = ")" if high_open or high is None else "]"
    allowed = f"a finite number in {lo}{'-inf' if low is None else low}, {'inf' if high is None else high}{hi}"
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{_owner(owner)}: {name} must be {allowed}, got {value!r}") from None
    if isinstance(value, bool) or not math.isfinite(x):
        raise ValueError(f"{_owner(owner)}: {name} must be {allowed}, got {value!r}")
    if low is not None and (x < low or (low_open and x == low)):
        raise ValueError(f"{_owner(owner)}: {name} must be {allowed}, got {value!r}")
    if high is not None and (x > high or (high_open and x == high)):
        raise ValueError(f"{_owner(owner)}: {name} must be {allowed}, got {value!r}")
    return x


def positive_int(owner: object, name: str, value: Any, *, minimum: int = 1) -> int:
    """Return ``value`` as an int >= ``minimum``, or raise ``ValueError``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ValueError(f"{_owner(owner)}: {name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def finite_array(
    owner: object,
    name: str,
    value: Any,
    *,
    shape: tuple[int | None, ...] | None = None,
    ndim: int | None = None,
) -> np.ndarray:
    """Return ``value`` as a float64 array with only finite entries, optionally of a given shape."""
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{_owner(owner)}: {name} must be an array of finite numbers, got {value!r}") from None
    if ndim is not None and arr.ndim != ndim:
        raise ValueError(f"{_owner(owner)}: {name} must have {ndim} dimension(s), got shape {arr.shape}")
    if shape is not None and (
        arr.ndim != len(shape) or any(s is not None and s != a for s, a in zip(shape, arr.shape, strict=True))
    ):
        want = "(" + ", ".join("any" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{_owner(owner)}: {name} must have shape {want}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{_owner(owner)}: {name} must contain only finite numbers, got {value!r}")
    return arr


def one_of(owner: object, name: str, value: Any, allowed: Iterable[Any]) -> Any:
    """Return ``value`` if it is one of ``allowed``, else raise ``ValueError``."""
    options = list(allowed)
    if value not in options:
        raise ValueError(f"{_owner(owner)}: {name} must be one of {options}, got {value!r}")
    return value


def flag(owner: object, name: str, value: Any) -> bool:
    """Return ``value`` if it is a bool, else raise ``ValueError``."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{_owner(owner)}: {name} must be True or False, got {value!r}")
    return bool(value)


def random_generator(owner: object, name: str, seed: Any) -> np.random.Generator:
    """A ``numpy.random.Generator`` from a seed (None, an int >= 0, a SeedSequence or a Generator)."""
    if seed is None or isinstance(seed, (np.random.Generator, np.random.SeedSequence)):
        return np.random.default_rng(seed)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(
            f"{_owner(owner)}: {name} must be None, an int >= 0, a SeedSequence or a Generator, got {seed!r}"
        )
    return np.random.default_rng(seed)


def unit_arg(owner: object, name: str, value: Any, *, optional: bool = False) -> str | None:
    """Return ``value`` if it is a unit string (or ``None`` when ``optional``), else raise ``ValueError``."""
    if isinstance(value, str) or (optional and value is None):
        return value
    allowed = "a string or None" if optional else "a string"
    raise ValueError(f"{_owner(owner)}: {name} must be {allowed}, got {value!r}")


def wrapped_arg(owner: object, name: str, value: Any, *, optional: bool = False) -> bool | None:
    """Return ``value`` as a bool (or ``None`` when ``optional``), else raise ``ValueError``."""
    if optional and value is None:
        return None
    if not isinstance(value, (bool, np.bool_)):
        allowed = "a bool or None" if optional else "a bool"
        raise ValueError(f"{_owner(owner)}: {name} must be {allowed}, got {value!r}")
    return bool(value)


def shape_arg(owner: object, name: str, value: Any, *, optional: bool = False) -> tuple[int, ...] | None:
    """Return ``value`` as a shape tuple (an int is a 1D shape; ``None`` when ``optional``), else raise."""
    if optional and value is None:
        return None
    dims = (value,) if isinstance(value, (int, np.integer)) else value
    try:
        ok = all(isinstance(d, (int, np.integer)) and not isinstance(d, bool) and d >= 0 for d in dims)
    except TypeError:
        ok = False
    if not ok:
        allowed = "a tuple of non-negative ints" + (" or None" if optional else "")
        raise ValueError(f"{_owner(owner)}: {name} must be {allowed}, got {value!r}")
    return tuple(int(d) for d in dims)


def block_with_ports(
    owner: object, name: str, value: Any, *, inputs: Iterable[str] = (), outputs: Iterable[str] = ()
) -> Any:
    """Return ``value`` if it is a Block with the named ports, else raise ``ValueError``.

    What a composite block checks of a block it is given to plug in (a motion computer, a
    corrector), so that a wrong one is refused when built rather than at ``connect``.
    """
    ins, outs = list(inputs), list(outputs)
    wanted = " and ".join(part for part in (f"inputs {ins}" if ins else "", f"outputs {outs}" if outs else "") if part)
    allowed = f"a Block with {wanted}" if wanted else "a Block"
    if not isinstance(value, Block):
        raise ValueError(f"{_owner(owner)}: {name} must be {allowed}, got {type(value).__name__}")
    missing = [f"input {p!r}" for p in ins if p not in value.inputs]
    missing += [f"output {p!r}" for p in outs if p not in value.outputs]
    if missing:
        raise ValueError(
            f"{_owner(owner)}: {name} must be {allowed}, got {type(value).__name__} without {', '.join(missing)}"
        )
    return value
