"""The block library."""

from cogblocks.blocks.blend import Blender
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
    "Constant",
    "Demux",
    "DiscreteLTI",
    "Function",
    "Gain",
    "Integrator",
    "KalmanEstimator",
    "KinematicPredictor",
    "KuramotoGroup",
    "KuramotoOscillator",
    "L1",
    "LowPass",
    "MeanPhaseMotion",
    "MotionComputer",
    "Mux",
    "OrderParameter",
    "PeriodEstimator",
    "PhaseComputer",
    "PhaseEstimator",
    "PhaseEstimator3D",
    "Playback",
    "PositionComputer",
    "Probe",
    "ReferenceCustomizer",
    "Saturation",
    "Select",
    "Substitute",
    "Sum",
    "UnitDelay",
    "fit_noise",
    "hilbert_phase",
    "ring_adjacency",
]
