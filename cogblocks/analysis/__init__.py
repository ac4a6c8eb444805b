"""Analysis tools: λ stability of the blender, linearisation of diagrams, optimisation-based blending.

Names are imported on first use: python-control, casadi and torch load slowly, and the
blender's compile-time stability check imports this package.
"""

import importlib
from typing import Any

_LAZY = {
    "KuramotoLinearization": "cogblocks.analysis.linearize",
    "kuramoto_jacobian": "cogblocks.analysis.linearize",
    "kuramoto_linearization": "cogblocks.analysis.linearize",
    "linearize": "cogblocks.analysis.linearize",
    "LambdaReport": "cogblocks.analysis.stability",
    "check_blender": "cogblocks.analysis.stability",
    "lambda_report": "cogblocks.analysis.stability",
    "OptimalBlender": "cogblocks.analysis.optimal_blending",
    "encoder_to_casadi": "cogblocks.analysis.optimal_blending",
}

__all__ = sorted(_LAZY)


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'cogblocks.analysis' has no attribute {name!r}")


def __dir__() -> list[str]:
    return __all__
