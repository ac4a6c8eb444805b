"""Offline analysis: linearisation of diagrams and of Kuramoto groups about their locked state.

Names are imported on first use: python-control loads slowly. The blender's λ stability check
lives beside the blender (:mod:`cogblocks.sync.stability`) and the optimisation-based blender in
:mod:`cogblocks.amplification.optimal`.
"""

import importlib
from typing import Any

_LAZY = {
    "KuramotoLinearization": "cogblocks.analysis.kuramoto",
    "kuramoto_jacobian": "cogblocks.analysis.kuramoto",
    "kuramoto_linearization": "cogblocks.analysis.kuramoto",
    "linearize": "cogblocks.analysis.linearization",
}

__all__ = sorted(_LAZY)


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'cogblocks.analysis' has no attribute {name!r}")


def __dir__() -> list[str]:
    return __all__
