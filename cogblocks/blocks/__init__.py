"""The block library."""

import importlib
from typing import Any

from cogblocks.blocks.blend import Blender
from cogblocks.blocks.buffer import Buffer
from cogblocks.blocks.core import (
    Constant,
    Demux,
    DiscreteLTI,
    Function,
    Gain,
    Integrator,
    LowPass,
    Mux,
    Playback,
    Probe,
    Saturation,
    Select,
    Substitute,
    Sum,
    UnitDelay,
)
from cogblocks.blocks.estimation import KalmanEstimator, fit_noise
from cogblocks.blocks.group import ArmPositions, KuramotoGroup, KuramotoOscillator, OrderParameter, ring_adjacency
from cogblocks.blocks.l1 import L1, KinematicPredictor
from cogblocks.blocks.motion import MeanPhaseMotion, MotionComputer
from cogblocks.blocks.phase import Algorithm1Phase, PhaseEstimator, hilbert_phase
from cogblocks.blocks.phase3d import (
    BackwardDifference,
    PeriodEstimator,
    PhaseComputer,
    PhaseEstimator3D,
    PositionComputer,
    ReferenceCustomizer,
)

__all__ = [
    "Algorithm1Phase",
    "ArmPositions",
    "BackwardDifference",
    "Blender",
    "Buffer",
    "Constant",
    "Demux",
    "DiscreteLTI",
    "EncoderClassifier",
    "Function",
    "Gain",
    "Integrator",
    "KalmanEstimator",
    "KinematicPredictor",
    "KuramotoGroup",
    "KuramotoOscillator",
    "L1",
    "LibraryProjector",
    "LowPass",
    "MeanPhaseMotion",
    "MotionComputer",
    "Mux",
    "NoCorrection",
    "OrderParameter",
    "PeriodEstimator",
    "PhaseComputer",
    "PhaseEstimator",
    "PhaseEstimator3D",
    "Playback",
    "PositionComputer",
    "Probe",
    "RLCorrector",
    "ReferenceCustomizer",
    "Saturation",
    "Select",
    "Substitute",
    "Sum",
    "UnitDelay",
    "VelocityBlender",
    "fit_noise",
    "hilbert_phase",
    "ring_adjacency",
]

# Blocks built on torch are imported on first use, so that the rest of the library loads fast.
_LAZY = {
    "EncoderClassifier": "cogblocks.blocks.encoding",
    "LibraryProjector": "cogblocks.blocks.encoding",
    "VelocityBlender": "cogblocks.blocks.encoding",
    "NoCorrection": "cogblocks.blocks.rl",
    "RLCorrector": "cogblocks.blocks.rl",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'cogblocks.blocks' has no attribute {name!r}")
