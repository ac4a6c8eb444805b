"""Length units of live streams: the factor that turns a stream's declared unit into a port's."""

from __future__ import annotations

__all__ = ["LENGTHS", "length_factor"]

#: Millimetres per unit of every length unit a stream may declare (whole numbers: m to mm is exactly 1000).
LENGTHS = {"m": 1000.0, "cm": 10.0, "mm": 1.0}


def length_factor(declared: str, wanted: str, what: str) -> float:
    """The factor from ``declared`` to ``wanted`` (1 when they are equal), or raise ``ValueError`` naming ``what``.

    Both must be equal, or both lengths of :data:`LENGTHS`.
    """
    if declared == wanted:
        return 1.0
    if declared in LENGTHS and wanted in LENGTHS:
        return LENGTHS[declared] / LENGTHS[wanted]
    allowed = f"{wanted!r}" + (f" or a length ({', '.join(LENGTHS)})" if wanted in LENGTHS else "")
    raise ValueError(f"{what} declares unit {declared!r}, the port expects {allowed}")
