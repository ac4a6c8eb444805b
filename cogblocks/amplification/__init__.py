"""The PoP of Amplification (section 5.1 and the appendix paper): buffer, encoder, the offline w̃ solver,
library projector, blending rules (table lookup and optimisation-based), position by integration,
the RL corrector, and the L2 architecture as one block.

Everything but the buffer is built on torch (and the optimised blender on casadi), so names are
imported on first use: this package loads fast.
"""

import importlib
from typing import Any

from cogblocks.amplification.buffer import Buffer

_LAZY = {
    "EncoderClassifier": "cogblocks.amplification.encoder",
    "EncoderNet": "cogblocks.amplification.encoder",
    "load_encoder": "cogblocks.amplification.encoder",
    "SolutionTable": "cogblocks.amplification.solution",
    "solution_table": "cogblocks.amplification.solution",
    "LibraryProjector": "cogblocks.amplification.projector",
    "VelocityBlender": "cogblocks.amplification.blending",
    "VelocityPositionComputer": "cogblocks.amplification.position",
    "CorrectorNet": "cogblocks.amplification.corrector",
    "NoCorrection": "cogblocks.amplification.corrector",
    "RLCorrector": "cogblocks.amplification.corrector",
    "load_corrector": "cogblocks.amplification.corrector",
    "OptimalBlender": "cogblocks.amplification.optimal",
    "L2Amplification": "cogblocks.amplification.l2",
}

__all__ = [
    "Buffer",
    "CorrectorNet",
    "EncoderClassifier",
    "EncoderNet",
    "L2Amplification",
    "LibraryProjector",
    "NoCorrection",
    "OptimalBlender",
    "RLCorrector",
    "SolutionTable",
    "VelocityBlender",
    "VelocityPositionComputer",
    "load_corrector",
    "load_encoder",
    "solution_table",
]


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'cogblocks.amplification' has no attribute {name!r}")


def __dir__() -> list[str]:
    return __all__
