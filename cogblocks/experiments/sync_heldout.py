"""Moved to :mod:`cogblocks.evaluation.sync_heldout`: this old path works for one release, with a DeprecationWarning."""

from __future__ import annotations

import importlib
import warnings
from typing import Any

NEW = "cogblocks.evaluation.sync_heldout"


def __getattr__(name: str) -> Any:
    module = importlib.import_module("cogblocks.evaluation.sync_heldout")
    if name.startswith("__") or not hasattr(module, name):
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    warnings.warn(f"{__name__} moved to {NEW}; import {name} from there", DeprecationWarning, stacklevel=2)
    return getattr(module, name)
