"""The window sweeps of a plan's search: ``(window, tail, knot)`` triples in seconds, checked for every planner."""

from __future__ import annotations

import math
from typing import Any

from cogblocks.sync.model import DT

__all__ = ["WHOLE_TRIAL_SWEEPS", "checked_sweeps"]

#: The sweeps of a plan of the whole trial (window, tail, knot in s): the bound's first sweep, then the thorough
#: bound's three passes. Looked at on validation groups 0-59 of ``random_groups(600, "validation", 0)``
#: (docs/validation/sync.md, "Every test run, in one table").
WHOLE_TRIAL_SWEEPS: tuple[tuple[float, float, float], ...] = (
    (4.0, 4.0, 0.25),
    (2.0, 6.0, 0.25),
    (10.0, 10.0, 0.5),
    (4.0, 4.0, 0.25),
)


def checked_sweeps(block: object, sweeps: Any) -> tuple[tuple[float, float, float], ...]:
    """``sweeps`` as (window, tail, knot) triples in s, checked for ``block``'s messages."""
    name = type(block).__name__
    try:
        checked = tuple((float(w), float(t), float(k)) for w, t, k in sweeps)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: sweeps must be (window, tail, knot) triples in s, got {sweeps!r}") from None
    for w, t, k in checked:
        ticks = [round(v / DT) for v in (w, t, k)]
        if not (all(math.isfinite(v) for v in (w, t, k)) and min(ticks[0], ticks[2]) >= 1 and ticks[1] >= 0):
            raise ValueError(f"{name}: a sweep needs window and knot >= {DT} s and tail >= 0, got {(w, t, k)}")
        if ticks[0] % ticks[2] or any(abs(v - n * DT) > 1e-9 for v, n in zip((w, t, k), ticks, strict=True)):
            raise ValueError(
                f"{name}: a sweep's times must be multiples of {DT} s and knot divide window, got {(w, t, k)}"
            )
    return checked
