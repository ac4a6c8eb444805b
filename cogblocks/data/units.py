"""Length units of recorded positions and live streams: one table, converted to the millimetres every port uses."""

from __future__ import annotations

__all__ = ["LENGTH_UNITS", "length_factor", "to_mm"]

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


def length_factor(declared: str, wanted: str, what: str) -> float:
    """The factor from ``declared`` to ``wanted`` (1 when they are equal), or raise ``ValueError`` naming ``what``.

    Both must be equal, or both lengths of :data:`LENGTH_UNITS` (a stream's or a port's unit, as declared).
    """
    if declared == wanted:
        return 1.0
    if declared in LENGTH_UNITS and wanted in LENGTH_UNITS:
        return LENGTH_UNITS[declared] / LENGTH_UNITS[wanted]
    allowed = f"{wanted!r}" + (f" or a length ({', '.join(LENGTH_UNITS)})" if wanted in LENGTH_UNITS else "")
    raise ValueError(f"{what} declares unit {declared!r}, the port expects {allowed}")
