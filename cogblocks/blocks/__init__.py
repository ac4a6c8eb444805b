"""General blocks, grouped by kind as in a Simulink or bdsim library.

- :mod:`~cogblocks.blocks.sources`: ``Constant``, ``Playback``
- :mod:`~cogblocks.blocks.functions`: ``Gain``, ``Sum``, ``Saturation``, ``Function``
- :mod:`~cogblocks.blocks.discrete`: ``UnitDelay``, ``Integrator``, ``BackwardDifference``, ``LowPass``,
  ``DiscreteLTI``
- :mod:`~cogblocks.blocks.routing`: ``Mux``, ``Demux``, ``Select``, ``Substitute``
- sinks: ``Probe`` (defined by the engine, which records it)

The blocks of the deliverable's architectures live in their own packages: :mod:`cogblocks.sync`,
:mod:`cogblocks.amplification`, :mod:`cogblocks.phase` and :mod:`cogblocks.sensing`.
"""

from typing import Any

from cogblocks.blocks.discrete import BackwardDifference, DiscreteLTI, Integrator, LowPass, UnitDelay
from cogblocks.blocks.functions import Function, Gain, Saturation, Sum
from cogblocks.blocks.routing import Demux, Mux, Select, Substitute
from cogblocks.blocks.sources import Constant, Playback
from cogblocks.sim.probe import Probe

__all__ = [
    "BackwardDifference",
    "Constant",
    "Demux",
    "DiscreteLTI",
    "Function",
    "Gain",
    "Integrator",
    "LowPass",
    "Mux",
    "Playback",
    "Probe",
    "Saturation",
    "Select",
    "Substitute",
    "Sum",
    "UnitDelay",
]

# Where the architecture blocks went in 0.2, so that an old import says where to look instead
# of a bare AttributeError. Plain strings: nothing is imported from the higher layers.
_MOVED = {
    **dict.fromkeys(
        (
            "KuramotoGroup",
            "KuramotoOscillator",
            "OrderParameter",
            "ArmPositions",
            "ring_adjacency",
            "Blender",
            "MotionComputer",
            "OscillatorMotion",
            "MeanPhaseMotion",
        ),
        "cogblocks.sync",
    ),
    **dict.fromkeys(
        ("Buffer", "EncoderClassifier", "LibraryProjector", "VelocityBlender", "RLCorrector", "NoCorrection"),
        "cogblocks.amplification",
    ),
    **dict.fromkeys(
        (
            "Algorithm1Phase",
            "PhaseEstimator",
            "PhaseEstimator3D",
            "PeriodEstimator",
            "ReferenceCustomizer",
            "PhaseComputer",
            "hilbert_phase",
        ),
        "cogblocks.phase",
    ),
    **dict.fromkeys(("KalmanEstimator", "fit_noise", "KinematicPredictor", "L1"), "cogblocks.sensing"),
}


def __getattr__(name: str) -> Any:
    if name == "PositionComputer":
        raise AttributeError(
            "cogblocks.blocks.PositionComputer was split in 0.2: use cogblocks.phase.PhasePositionComputer "
            "(phase → position, section 6) or cogblocks.amplification.VelocityPositionComputer (integration)"
        )
    if name in _MOVED:
        raise AttributeError(
            f"{name} moved to {_MOVED[name]} in 0.2: use 'from {_MOVED[name]} import {name}' (see docs/architecture.md)"
        )
    raise AttributeError(f"module 'cogblocks.blocks' has no attribute {name!r}")
