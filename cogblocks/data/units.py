"""Length units of recorded positions, converted to the millimetres every port of the package uses."""

from __future__ import annotations

__all__ = ["LENGTH_UNITS", "to_mm"]

#: Millimetres per unit, for each length unit a file or stream may declare.
LENGTH_UNITS: dict[str, float] = {"m": 1000.0, "cm": 10.0, "mm": 1.0}


def to_mm(unit: str, where: str) -> float:
    """The factor that turns lengths in ``unit`` into millimetres.

    Parameters
    ----------
    unit : str
        A declared length unit: ``"m"``, ``"cm"`` or ``"mm"`` (case and surrounding blanks ignored).
    where : str
        What declared it (a file and its field, a parameter), named in the error.

    Raises
    ------
    ValueError
        If ``unit`` is not one of :data:`LENGTH_UNITS`, naming it and ``where``.
    """
    key = str(unit).strip().lower() if isinstance(unit, str) else None
    if key not in LENGTH_UNITS:
        raise ValueError(f"{where}: unit {unit!r} is not a length unit (allowed: {', '.join(LENGTH_UNITS)})")
    return LENGTH_UNITS[key]
