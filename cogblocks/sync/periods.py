"""Decision periods in seconds: one keyword, ``decide_every``, for every motion computer that decides in periods.

A period is given in seconds and counted in ticks of the block's step when the diagram is compiled, so that the
same setting means the same time at any step. For one release a period given the old way still works, with a
:class:`DeprecationWarning`: an ``int`` given to ``decide_every`` (its former unit, ticks) or an old keyword
(``replan_every``, ticks) is read as that many ticks.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np

from cogblocks.sim.params import finite_number, positive_int
from cogblocks.sim.timing import BASE_STEP

__all__ = ["block_step", "decision_period", "period_ticks", "seconds_ticks"]


def block_step(block: Any) -> float:
    """The block's step (s): the compiled one, else its own period, else the base step."""
    if getattr(block, "dt", None):
        return block.dt * block.every
    return block.period or BASE_STEP


def decision_period(
    block: Any, value: Any, *, old_name: str = "", old_value: Any = None, stacklevel: int = 3
) -> tuple[float, int | None]:
    """``(seconds, ticks)`` of ``block``'s ``decide_every``; ``ticks`` is ``None`` unless given the old way.

    ``old_value`` is what the deprecated keyword ``old_name`` (ticks) was given (``None``: not given). The warning
    names the frame ``stacklevel`` up (3: the caller of the constructor that calls this).
    """
    if old_value is not None:
        ticks, given = positive_int(block, old_name, old_value), f"{old_name} (ticks) is deprecated"
    elif isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        ticks = positive_int(block, "decide_every", value)
        given = "decide_every is in seconds; an int is read as ticks for one release"
    else:
        return finite_number(block, "decide_every", value, low=0.0, low_open=True), None
    warnings.warn(
        f"{type(block).__name__}: {given}; give decide_every in seconds "
        f"({ticks} ticks of {BASE_STEP:g} s: decide_every={ticks * BASE_STEP:g})",
        DeprecationWarning,
        stacklevel=stacklevel,
    )
    return ticks * block_step(block), ticks


def period_ticks(block: Any, seconds: float, ticks: int | None) -> int:
    """The period in ticks of ``block``'s step (a period given in ticks stays as given).

    Raises
    ------
    ValueError
        When ``seconds`` is not a whole, positive number of the block's steps.
    """
    if ticks is not None:
        return ticks
    step = block_step(block)
    count = round(seconds / step)
    if count < 1 or abs(seconds - count * step) > 1e-9:
        raise ValueError(
            f"{type(block).__name__}: decide_every must be a positive multiple of the block's step ({step:g} s), "
            f"got {seconds!r}"
        )
    return count


def seconds_ticks(block: Any, name: str, value: Any, step: float = BASE_STEP) -> int:
    """``block``'s parameter ``name`` (seconds) as a whole, positive number of ticks of ``step``.

    Raises
    ------
    ValueError
        When ``value`` is not a finite number of seconds that is a positive multiple of ``step``.
    """
    seconds = finite_number(block, name, value, low=0.0, low_open=True)
    ticks = round(seconds / step)
    if ticks < 1 or abs(seconds - ticks * step) > 1e-9:
        raise ValueError(f"{type(block).__name__}: {name} must be a positive multiple of {step:g} s, got {value!r}")
    return ticks
