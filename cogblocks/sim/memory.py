"""How much memory one allocation of a run may take, so that a run too big for the machine is refused up front.

The limit is half the memory available when asked (``psutil``, or ``os.sysconf`` on POSIX), leaving
room for the rest of the run and the other programs; set the environment variable
``COGBLOCKS_MEMORY_LIMIT`` (bytes, or with a suffix: ``512M``, ``8G``) to choose it yourself, or to
``0`` to switch the check off.
"""

from __future__ import annotations

import os

__all__ = ["MEMORY_LIMIT_ENV", "check_memory", "describe_bytes", "memory_limit"]

MEMORY_LIMIT_ENV = "COGBLOCKS_MEMORY_LIMIT"
_SUFFIXES = {"": 1, "K": 2**10, "M": 2**20, "G": 2**30, "T": 2**40}


def _available() -> int | None:
    try:
        import psutil

        return int(psutil.virtual_memory().available)
    except ImportError:
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):  # not POSIX: no estimate, no check
        return None


def memory_limit() -> int | None:
    """Bytes one allocation may take (``None``: unchecked), from ``COGBLOCKS_MEMORY_LIMIT`` or the machine."""
    text = os.environ.get(MEMORY_LIMIT_ENV, "").strip().upper().removesuffix("B").removesuffix("I")
    if text:
        number, unit = (text[:-1], text[-1]) if text[-1] in _SUFFIXES else (text, "")
        try:
            value = float(number) * _SUFFIXES[unit]
        except ValueError:
            raise ValueError(
                f"{MEMORY_LIMIT_ENV}={os.environ[MEMORY_LIMIT_ENV]!r}: give bytes, or a number with K, M, G or T"
            ) from None
        return None if value <= 0 else int(value)
    available = _available()
    return None if available is None else available // 2


def describe_bytes(n: float) -> str:
    """``n`` bytes in the largest binary unit that keeps a number >= 1: ``"26.8 GiB"``."""
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024:
            return f"{n:.1f} {unit}" if unit != "B" else f"{n:.0f} B"
        n /= 1024
    return f"{n:.1f} TiB"


def check_memory(nbytes: float, what: str, way_out: str) -> None:
    """Refuse an allocation larger than :func:`memory_limit`.

    Raises
    ------
    ValueError
        Naming ``what`` needs the memory, how much, the limit and ``way_out``.
    """
    limit = memory_limit()
    if limit is not None and nbytes > limit:
        source = f"{MEMORY_LIMIT_ENV}" if os.environ.get(MEMORY_LIMIT_ENV, "").strip() else "half the available memory"
        raise ValueError(
            f"{what} needs about {describe_bytes(nbytes)}, more than the {describe_bytes(limit)} allowed "
            f"({source}; set {MEMORY_LIMIT_ENV} to change it): {way_out}"
        )
