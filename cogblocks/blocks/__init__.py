"""The block library."""

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
    Sum,
    UnitDelay,
)
from cogblocks.blocks.group import KuramotoGroup, KuramotoOscillator, OrderParameter, ring_adjacency

__all__ = [
    "Constant",
    "Demux",
    "DiscreteLTI",
    "Function",
    "Gain",
    "Integrator",
    "KuramotoGroup",
    "KuramotoOscillator",
    "LowPass",
    "Mux",
    "OrderParameter",
    "Playback",
    "Probe",
    "Saturation",
    "Sum",
    "UnitDelay",
    "ring_adjacency",
]
