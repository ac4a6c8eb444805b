"""Old import paths that forward to a module's new place for one release, with a DeprecationWarning."""

from __future__ import annotations

import importlib
import warnings
from collections.abc import Callable
from typing import Any

__all__ = ["forwarding"]


def forwarding(old: str, new: str) -> Callable[[str], Any]:
    """A module ``__getattr__`` for the module ``old`` that moved to ``new``.

    Each public name read from ``old`` is ``new``'s, with a :class:`DeprecationWarning` that names ``new``;
    a name ``new`` lacks is an :class:`AttributeError` naming ``old``.
    """

    def __getattr__(name: str) -> Any:
        module = importlib.import_module(new)
        if name.startswith("__") or not hasattr(module, name):
            raise AttributeError(f"module {old!r} has no attribute {name!r}")
        warnings.warn(f"{old} moved to {new}; import {name} from there", DeprecationWarning, stacklevel=2)
        return getattr(module, name)

    return __getattr__
