"""Signal specs: what travels on a wire (shape, dtype, unit, wrapped angle)."""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

__all__ = ["Signal", "ANY", "spec_from", "unit_product"]

_FACTOR = re.compile(r"^([A-Za-z_%°µ][A-Za-z0-9_%°µ]*)(?:\^(-?\d+))?$")


def _as_shape(shape: Any) -> tuple[int, ...] | None:
    if shape is None:
        return None
    if isinstance(shape, (int, np.integer)):
        shape = (int(shape),)
    # a string is iterable and int("3") works: refuse it rather than read "three" letter by letter
    if isinstance(shape, (str, bytes)) or not hasattr(shape, "__iter__"):
        raise ValueError(f"shape must be a tuple of non-negative ints, got {shape!r}")
    if not all(isinstance(s, (int, np.integer)) and not isinstance(s, bool) for s in shape):
        raise ValueError(f"shape must be a tuple of non-negative ints, got {shape!r}")
    out = tuple(int(s) for s in shape)
    if any(s < 0 for s in out):
        raise ValueError(f"shape must be a tuple of non-negative ints, got {shape!r}")
    return out


@dataclass(frozen=True)
class Signal:
    """The spec of a signal carried by a port.

    Parameters
    ----------
    shape : tuple of int, int or None
        Array shape of one sample; ``()`` is a scalar. ``None`` on an input means
        "any shape".
    dtype : numpy dtype-like or None
        Element type, ``float64`` by default. ``None`` on an input means "any".
    unit : str or None
        Physical unit, for instance ``"rad"``, ``"mm"``, ``"mm/s"`` or ``"1"`` for
        dimensionless. ``None`` on an input means "any unit".
    wrapped : bool or None
        Whether the signal is an angle wrapped to one turn. ``None`` on an input
        means "either".

    Notes
    -----
    Two specs are compatible when every field that both of them fix is equal. An
    input declared with ``None`` fields accepts any value of those fields; an
    output's spec must be concrete once the diagram is compiled.
    """

    shape: tuple[int, ...] | None = ()
    dtype: Any = np.float64
    unit: str | None = "1"
    wrapped: bool | None = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "shape", _as_shape(self.shape))
        if self.dtype is not None:
            object.__setattr__(self, "dtype", np.dtype(self.dtype))
        if self.unit is not None and not isinstance(self.unit, str):
            raise ValueError(f"unit must be a string or None, got {self.unit!r}")
        if self.wrapped is not None and not isinstance(self.wrapped, (bool, np.bool_)):
            raise ValueError(f"wrapped must be a bool or None, got {self.wrapped!r}")

    @property
    def concrete(self) -> bool:
        """True when no field is left open."""
        # ``is`` rather than ``in``: numpy compares dtype('float64') == None as True
        return all(v is not None for v in (self.shape, self.dtype, self.unit, self.wrapped))

    def mismatch(self, other: Signal) -> str | None:
        """Describe the first field on which ``self`` and ``other`` disagree, or None."""
        for field in ("shape", "dtype", "unit", "wrapped"):
            a, b = getattr(self, field), getattr(other, field)
            if a is not None and b is not None and a != b:
                return f"{field} {a!r} != {b!r}"
        return None

    def merge(self, other: Signal) -> Signal:
        """The spec that fixes every field either of the two fixes (they must agree)."""
        return Signal(
            shape=self.shape if self.shape is not None else other.shape,
            dtype=self.dtype if self.dtype is not None else other.dtype,
            unit=self.unit if self.unit is not None else other.unit,
            wrapped=self.wrapped if self.wrapped is not None else other.wrapped,
        )

    def with_(self, **changes: Any) -> Signal:
        """A copy with some fields changed."""
        return replace(self, **changes)

    def zeros(self) -> np.ndarray:
        """A zero-filled array holding one sample of this (concrete) signal."""
        return np.zeros(self.shape, dtype=self.dtype)

    def __str__(self) -> str:
        def show(v: Any, fmt: Any = repr) -> str:
            return "any" if v is None else fmt(v)

        shape = show(self.shape, lambda s: "(" + ", ".join(map(str, s)) + ("," if len(s) == 1 else "") + ")")
        return (
            f"Signal(shape={shape}, dtype={show(self.dtype, str)}, "
            f"unit={show(self.unit)}, wrapped={show(self.wrapped)})"
        )


#: An input spec that accepts any signal.
ANY = Signal(shape=None, dtype=None, unit=None, wrapped=None)


_SPEC_FIELDS = ("shape", "dtype", "unit", "wrapped")


def spec_from(owner: str, name: str, spec: Signal | None, fields: dict[str, Any], defaults: Signal) -> Signal:
    """The spec a port declaration asks for: ``spec``, or ``defaults`` with ``fields`` changed (not both);
    a bad field raises naming ``owner.name``."""
    unknown = set(fields) - set(_SPEC_FIELDS)
    if unknown:
        raise TypeError(f"unknown signal field(s) {sorted(unknown)}; allowed: {list(_SPEC_FIELDS)}")
    if spec is not None:
        if fields:
            raise TypeError("give either a Signal spec or its fields, not both")
        return spec
    try:
        return defaults.with_(**fields) if fields else defaults
    except ValueError as exc:  # a bad unit/shape/wrapped given to the block's constructor: say whose
        raise ValueError(f"{owner}.{name}: {exc}") from None


def _unit_powers(unit: str) -> dict[str, int]:
    """``"mm/s^2"`` as ``{"mm": 1, "s": -2}``; ``"1"`` as ``{}``."""
    powers: dict[str, int] = {}
    numerator, *denominators = unit.replace(" ", "").split("/")
    for sign, part in [(1, numerator), *((-1, d) for d in denominators)]:
        for factor in part.split("*"):
            if factor == "1" and sign == 1:
                continue
            match = _FACTOR.match(factor)
            if match is None:
                raise ValueError(
                    f"cannot multiply the unit {unit!r}: {factor!r} is not a unit name with an integer power"
                )
            name, power = match.group(1), int(match.group(2) or 1)
            powers[name] = powers.get(name, 0) + sign * power
    return powers


def unit_product(a: str, b: str) -> str:
    """The unit of a product: ``unit_product("rad", "1/s") == "rad/s"``, ``unit_product("mm/s", "s") == "mm"``.

    Units are names joined by ``*`` and ``/`` with optional integer powers (``"mm/s^2"``); ``"1"``
    is dimensionless. Powers of a name add up and cancel.
    """
    powers = _unit_powers(a)
    for name, power in _unit_powers(b).items():
        powers[name] = powers.get(name, 0) + power

    def show(name: str, power: int) -> str:
        return name if power == 1 else f"{name}^{power}"

    up = "*".join(show(n, p) for n, p in powers.items() if p > 0) or "1"
    down = "".join("/" + show(n, -p) for n, p in powers.items() if p < 0)
    return up + down
