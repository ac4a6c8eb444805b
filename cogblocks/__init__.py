"""cogblocks: the cognitive architectures of L1/L2 virtual humans as composable discrete-time blocks."""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from cogblocks.sim import Block, Diagram, DiagramError, Signal, Simulator, Trace

__version__ = "0.2.0"

__all__ = ["Block", "Diagram", "DiagramError", "Signal", "Simulator", "Trace", "__version__"]


def __getattr__(name: str) -> Any:
    """The engine's names, imported on first use: ``import cogblocks`` alone loads nothing heavy, so the
    command line starts (and stops on Ctrl-C) before NumPy loads."""
    if name in __all__ or name == "sim":
        sim = importlib.import_module("cogblocks.sim")
        return sim if name == "sim" else getattr(sim, name)
    raise AttributeError(f"module 'cogblocks' has no attribute {name!r}")
